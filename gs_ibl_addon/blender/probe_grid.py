"""The probe grid (an irradiance volume) in Blender: order-2 SH probes on an nx x ny x nz grid over a region,
stored in one small float image and interpolated trilinearly per shading point by the local-light group
(blender/local_light.py). One grid per file; the meshes it lights carry ``gs_ibl_grid``.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.probe.grid import POINT_FACE_SIZE, GridSpec, pack_grid
from . import local_light as ll
from .object_probes import Progress, coefficients_with_world, probe_renderer, world_box


def region_box(region: bpy.types.Object | None, objects: list[bpy.types.Object]) -> tuple[np.ndarray, np.ndarray]:
    """The grid's box: an Empty's (its display size times its world scale, about its location; rotation is not
    followed), else the union of the objects' bounds."""
    if region is not None:
        if region.type != "EMPTY":
            raise ValueError(f"Grid Region {region.name!r} must be an Empty (Add > Empty > Cube)")
        half = np.abs(np.array(region.matrix_world.to_scale())) * float(region.empty_display_size)
        centre = np.array(region.matrix_world.translation)
        return centre - half, centre + half
    if not objects:
        raise ValueError("No region for the grid: pick a Grid Region Empty, or select the meshes it should light")
    boxes = [world_box(o) for o in objects]
    return np.min([b[0] for b in boxes], 0), np.max([b[1] for b in boxes], 0)


def bake_probe_grid(scene: bpy.types.Scene, probe: bpy.types.Object, objects: list[bpy.types.Object],
                    progress: Progress | None = None) -> tuple[str, GridSpec, np.ndarray]:
    """Bake the grid over the probe's Grid Region and light ``objects`` with it. Returns (report line, grid,
    its monomial coefficients minus the World's, (nx, ny, nz, 9, 3))."""
    s = probe.gs_ibl_probe
    lo, hi = region_box(s.grid_region, objects)
    spec = GridSpec(tuple(float(c) for c in lo), tuple(float(c) for c in hi), tuple(int(n) for n in s.grid_resolution))
    r = probe_renderer(scene, probe, need_world=True)  # checks the probe, its splats and World before any work
    d_world, d = coefficients_with_world(probe, r, spec.points().reshape(-1, 3), progress)
    delta = d.reshape(*spec.shape, *d.shape[1:]) - d_world
    image = ll.grid_image(pack_grid(delta))
    ll.local_light_group(spec, image)
    for obj in objects:
        ll.set_object_coefficients(obj, None, grid=True)
        ll.light_object(obj, float(s.strength))
        obj.update_tag()
    nx, ny, nz = spec.shape
    text = (f"Probe grid {nx}x{ny}x{nz} ({spec.count} probes, {POINT_FACE_SIZE}x{POINT_FACE_SIZE} faces) over "
            f"({', '.join(f'{c:.2f}' for c in lo)}) .. ({', '.join(f'{c:.2f}' for c in hi)}) "
            f"lights {len(objects)} meshes")
    s.local_report = text
    return text, spec, delta
