"""Lighting "Auto": every lit mesh gets the light it needs (core/probe/auto_light.py), without being asked.

After the World probe's bake, probes at each lit mesh's centre and box corners are baked in one batch with one at
the World probe's place (the measurement); a mesh whose light differs from the World's gets its centre's probe, and
one whose light varies across it a grid (a second batch of the grid nodes not measured already), through the
local-light group (blender/local_light.py), which adds the difference to the World's light. A mesh the World lights well
enough costs its nine probes. Re-decided when a lit mesh moves (Update When Moved) and at every bake.
"""
from __future__ import annotations

import bpy
import numpy as np

from ...core.probe.auto_light import (MEASURE_FACE, LightChoice, choose_light, measure_points, measured_nodes,
                                     mesh_grid)
from . import local_light as ll
from ..common.jobs import Job, Progress, Work, run_now
from .object_probes import lit_meshes, point_coefficients, probe_renderer_steps, world_box

REPORT_PREFIX = "Auto lighting: "
AUTO_KEY = "gs_ibl_auto_light"  # on a mesh Lighting Auto lit: the probe that did (its light is that probe's to undo)


def remove_auto_light(scene: bpy.types.Scene, probe: bpy.types.Object) -> int:
    """Take the light Lighting Auto gave meshes off them (the probe is set to World Probe); what the local-light
    operators gave stays. Returns how many meshes changed."""
    n = 0
    for obj in scene.objects:
        if obj.get(AUTO_KEY) == probe.name:
            if ll.has_local_light(obj):
                ll.unlight_object(obj)
            del obj[AUTO_KEY]
            n += 1
    return n


def auto_light(scene: bpy.types.Scene, probe: bpy.types.Object, objects: list[bpy.types.Object] | None = None,
               progress: Progress | None = None) -> tuple[str, list[LightChoice]]:
    """Choose and apply each mesh's light (``objects``, default: the meshes inside the probe's splats' bounds);
    returns (the report line, the choices). auto_light_steps run now."""
    return run_now(auto_light_steps(scene, probe, objects), progress)


def _probes(renderer, points: np.ndarray, progress: Progress) -> np.ndarray:
    """A worker's batch of the measurement's probes (object_probes.point_coefficients, with the job's progress)."""
    return point_coefficients(renderer, points, lambda done, total: progress(
        f"baking {done} of {total} light probes for each mesh's light", done / max(total, 1)), MEASURE_FACE)


def auto_light_steps(scene: bpy.types.Scene, probe: bpy.types.Object,
                     objects: list[bpy.types.Object] | None = None) -> Job:
    """auto_light as a job (blender/jobs.py): the probes' two batches on a worker, Blender read before and written
    after on the main thread."""
    meshes = lit_meshes(scene, probe) if objects is None else list(objects)
    if not meshes:
        return "", []
    r = yield from probe_renderer_steps(scene, probe, need_world=True)
    scene_name, probe_name, names = scene.name, probe.name, [o.name for o in meshes]
    tol = float(probe.gs_ibl_probe.variation_tolerance)
    boxes = [world_box(o) for o in meshes]
    points = np.concatenate([measure_points(*box) for box in boxes])
    at = np.array(probe.matrix_world.translation, np.float64)
    # the measurement, one batch with the World probe's place (their difference carries no difference of method)
    both = yield Work(_probes, r, np.vstack([at[None], points]), span=(0.0, 0.4))
    d_world, d = both[0], both[1:]
    choices = [choose_light(n, d_world, d[9 * i:9 * i + 9], tol) for i, n in enumerate(names)]
    # light of their own, at the operators' size, for the meshes that need it: one more batch
    keys, tiles, grids = {}, {}, {}  # grids: {mesh index: its grid}
    for i, (name, box, c) in enumerate(zip(names, boxes, choices)):
        if c.kind == "probe":  # its centre's measurement is its probe
            keys[name] = f"probe:{name}"
            tiles[keys[name]] = ll.probe_tile(points[9 * i], d[9 * i] - d_world)
        elif c.kind == "grid":
            keys[name] = f"object:{name}"
            grids[i] = mesh_grid(*box, c.variation)
    if grids:  # the grids' nodes the measurement did not place: one more batch
        reuse = {i: measured_nodes(spec, points[9 * i:9 * i + 9]) for i, spec in grids.items()}
        fresh = {i: spec.points().reshape(-1, 3)[reuse[i] < 0] for i, spec in grids.items()}
        todo = np.concatenate(list(fresh.values()))
        dg = (yield Work(_probes, r, todo, span=(0.4, 0.95))) if len(todo) else np.empty((0, *d.shape[1:]))
        start = 0
        for i, spec in grids.items():
            m = reuse[i]
            nodes = np.empty((spec.count, *d.shape[1:]))
            nodes[m >= 0] = d[9 * i + m[m >= 0]]
            nodes[m < 0] = dg[start:start + len(fresh[i])]
            start += len(fresh[i])
            tiles[keys[names[i]]] = (spec, nodes.reshape(*spec.shape, *d.shape[1:]) - d_world)
    scene = bpy.data.scenes.get(scene_name)  # after the workers: by name (see blender/bake.py _named)
    probe = scene.objects.get(probe_name) if scene is not None else None
    if probe is None:
        raise ValueError(f"{probe_name!r} was deleted while its meshes' light was chosen: nothing was written")
    meshes = [scene.objects.get(n) for n in names]
    for obj, c in zip(meshes, choices):
        if obj is None:
            continue  # deleted meanwhile
        if c.kind == "world":
            if ll.has_local_light(obj):
                ll.unlight_object(obj)
            obj.pop(AUTO_KEY, None)
            continue
        ll.set_object_grid(obj, keys[obj.name])
        ll.light_object(obj, float(probe.gs_ibl_probe.strength))
        obj[AUTO_KEY] = probe.name
    if tiles:
        ll.store_grids(tiles, d_world, probe.gs_ibl_probe.irradiance_image)
    if objects is None:  # a whole bake: the More Than One Probe panel lists why each mesh got what it got
        probe.gs_ibl_probe.local_report = "\n".join(c.message() for c in choices)
    counts = {k: sum(c.kind == k for c in choices) for k in ("world", "probe", "grid")}
    text = (f"{REPORT_PREFIX}{len(choices)} meshes: {counts['world']} by the World probe, {counts['probe']} with a "
            f"probe of their own, {counts['grid']} with a grid")
    return text, choices
