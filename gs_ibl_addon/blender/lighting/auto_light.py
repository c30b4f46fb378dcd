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

from ...core.probe.auto_light import MEASURE_FACE, AutoLight, LightChoice, auto_light_batches
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
    at = np.array(probe.matrix_world.translation, np.float64)
    # the measurement, one batch with the World probe's place (their difference carries no difference of method);
    # then, for the meshes that need a grid, one more batch of its nodes
    batches, spans = auto_light_batches(at, boxes, names, tol), iter([(0.0, 0.4), (0.4, 0.95)])
    try:
        points = next(batches)
        while True:
            points = batches.send((yield Work(_probes, r, points, span=next(spans))))
    except StopIteration as done:
        light: AutoLight = done.value
    choices = light.choices
    keys, tiles = {}, {}
    for i, (name, c) in enumerate(zip(names, choices)):
        if c.kind == "probe":  # its centre's measurement is its probe
            keys[name] = f"probe:{name}"
            tiles[keys[name]] = ll.probe_tile(light.points[i, 0], light.measured[i, 0] - light.d_world)
        elif c.kind == "grid":
            keys[name] = f"object:{name}"
            spec, nodes = light.grids[i]
            tiles[keys[name]] = (spec, nodes - light.d_world)
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
        ll.store_grids(tiles, light.d_world, probe.gs_ibl_probe.irradiance_image)
    if objects is None:  # a whole bake: the More Than One Probe panel lists why each mesh got what it got
        probe.gs_ibl_probe.local_report = "\n".join(c.message() for c in choices)
    counts = {k: sum(c.kind == k for c in choices) for k in ("world", "probe", "grid")}
    text = (f"{REPORT_PREFIX}{len(choices)} mesh{'es' if len(choices) != 1 else ''}: {counts['world']} by the World "
            f"probe, {counts['probe']} with a probe of their own, {counts['grid']} with a grid")
    return text, choices
