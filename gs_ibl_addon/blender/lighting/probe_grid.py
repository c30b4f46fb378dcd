"""The probe grid (an irradiance volume) in Blender: order-2 SH probes on an nx x ny x nz grid over a region,
stored as tiles of one small float image (the atlas) and interpolated trilinearly per shading point by the
local-light group (blender/local_light.py). A grid spans the probe's Grid Region (one grid for all the meshes), or
each mesh's own bounds (one grid each); each mesh points at its tile through custom properties.
"""
from __future__ import annotations

import bpy
import numpy as np

from ...core.probe.grid import POINT_FACE_SIZE, GridSpec
from . import local_light as ll
from .object_probes import Progress, coefficients_with_world, probe_renderer, world_box


def region_box(region: bpy.types.Object) -> tuple[np.ndarray, np.ndarray]:
    """An Empty's box: its display size times its world scale, about its location (rotation is not followed)."""
    if region.type != "EMPTY":
        raise ValueError(f"Grid Region {region.name!r} must be an Empty (Add > Empty > Cube)")
    half = np.abs(np.array(region.matrix_world.to_scale())) * float(region.empty_display_size)
    centre = np.array(region.matrix_world.translation)
    return centre - half, centre + half


def grid_specs(region: bpy.types.Object | None, objects: list[bpy.types.Object],
               shape) -> dict[str, tuple[GridSpec, list[bpy.types.Object]]]:
    """{atlas key: (grid, the objects it lights)}: one grid over the region for all objects, or, without a region,
    one grid over each object's own bounds."""
    shape = tuple(int(n) for n in shape)
    if region is not None:
        lo, hi = region_box(region)
        return {f"region:{region.name}": (GridSpec(tuple(map(float, lo)), tuple(map(float, hi)), shape), objects)}
    if not objects:
        raise ValueError("No mesh to light: select meshes, or pick a Grid Region Empty")
    out = {}
    for o in objects:
        lo, hi = world_box(o)
        out[f"object:{o.name}"] = (GridSpec(tuple(map(float, lo)), tuple(map(float, hi)), shape), [o])
    return out


def bake_probe_grid(scene: bpy.types.Scene, probe: bpy.types.Object, objects: list[bpy.types.Object],
                    progress: Progress | None = None) -> tuple[str, dict[str, tuple[GridSpec, np.ndarray]]]:
    """Bake grids (one over the probe's Grid Region, or one over each mesh's bounds) and light ``objects`` with
    them. Returns (report line, {atlas key: (grid, its monomial coefficients minus the World's (nx, ny, nz, 9, 3))})."""
    s = probe.gs_ibl_probe
    specs = grid_specs(s.grid_region, objects, s.grid_resolution)  # bad input refused before any work
    r = probe_renderer(scene, probe, need_world=True)  # checks the probe, its splats and World before any work
    points = np.concatenate([spec.points().reshape(-1, 3) for spec, _ in specs.values()])
    d_world, d = coefficients_with_world(probe, r, points, progress)
    grids, start = {}, 0
    for key, (spec, objs) in specs.items():
        delta = d[start:start + spec.count].reshape(*spec.shape, *d.shape[1:]) - d_world
        start += spec.count
        grids[key] = (spec, delta)
        for obj in objs:
            ll.set_object_grid(obj, key)
            ll.light_object(obj, float(s.strength))
    ll.store_grids(grids, d_world, s.irradiance_image)
    nx, ny, nz = next(iter(specs.values()))[0].shape
    where = (f"over Grid Region {s.grid_region.name!r}" if s.grid_region is not None
             else "over each mesh's own bounds")
    text = (f"Probe grid {nx}x{ny}x{nz} {where}: {len(points)} probes ({POINT_FACE_SIZE}x{POINT_FACE_SIZE} faces) "
            f"light {len(objects)} meshes")
    s.local_report = text
    return text, grids
