"""Lighting "Auto": every lit mesh gets the light it needs (core/probe/auto_light.py), without being asked.

After the World probe's bake, probes on a small grid over each lit mesh are baked in one batched submission with
one at the World probe's place; each mesh then keeps the World's light, or gets its own probe or its grid through
the local-light group (blender/local_light.py), which adds the difference to the World's light. Re-decided when a
lit mesh moves (Update When Moved) and at every bake.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.probe.auto_light import LightChoice, centre_index, choose_light, mesh_grid
from . import local_light as ll
from .object_probes import Progress, coefficients_with_world, lit_meshes, probe_renderer, world_box

REPORT_PREFIX = "Auto lighting: "


def auto_light(scene: bpy.types.Scene, probe: bpy.types.Object, objects: list[bpy.types.Object] | None = None,
               progress: Progress | None = None) -> tuple[str, list[LightChoice]]:
    """Choose and apply each mesh's light (``objects``, default: the meshes inside the probe's splats' bounds);
    returns (the report line, the choices)."""
    meshes = lit_meshes(scene, probe) if objects is None else list(objects)
    if not meshes:
        return "", []
    r = probe_renderer(scene, probe, need_world=True)
    specs = [mesh_grid(*world_box(o)) for o in meshes]
    points = np.concatenate([spec.points().reshape(-1, 3) for spec in specs])
    d_world, d = coefficients_with_world(probe, r, points, progress)  # one batch: the World's place and every node
    tol = float(probe.gs_ibl_probe.variation_tolerance)
    tiles, choices, start = {}, [], 0
    for obj, spec in zip(meshes, specs):
        d_grid = d[start:start + spec.count].reshape(*spec.shape, *d.shape[1:])
        start += spec.count
        choice = choose_light(obj.name, spec, d_world, d_grid, tol)
        choices.append(choice)
        if choice.kind == "world":
            if ll.has_local_light(obj):
                ll.unlight_object(obj)
            continue
        if choice.kind == "probe":
            key = f"probe:{obj.name}"
            tiles[key] = ll.probe_tile(spec.points()[centre_index(spec)], d_grid[centre_index(spec)] - d_world)
        else:
            key = f"object:{obj.name}"
            tiles[key] = (spec, d_grid - d_world)
        ll.set_object_grid(obj, key)
        ll.light_object(obj, float(probe.gs_ibl_probe.strength))
    if tiles:
        ll.store_grids(tiles)
    if objects is None:  # a whole bake: the More Than One Probe panel lists why each mesh got what it got
        probe.gs_ibl_probe.local_report = "\n".join(c.message() for c in choices)
    counts = {k: sum(c.kind == k for c in choices) for k in ("world", "probe", "grid")}
    text = (f"{REPORT_PREFIX}{len(choices)} meshes: {counts['world']} by the World probe, {counts['probe']} with a "
            f"probe of their own, {counts['grid']} with a grid")
    return text, choices
