"""Where one probe is not enough: which meshes it misleads (Check Light Variation) and per-object probes.

Both bake cheap order-2 SH probes (core/probe/grid.py bake_sh_points) from the probe's splats, on the GPU
renderer the probe's own bakes use (splat_cache). A per-object probe is baked at the mesh's bounds centre and
lights the mesh through the local-light group (blender/local_light.py) as the difference to the World probe's
light, so the World keeps the background and the specular.
"""
from __future__ import annotations

from typing import Callable

import bpy
import numpy as np
from mathutils import Vector

from ...core.probe.grid import POINT_FACE_SIZE, bake_sh_points, monomial_coefficients
from ...core.probe.variation import Variation, box_points, variation_from_sh
from ...core.render.renderer import BAKE_KEEP_SHARE
from . import local_light as ll
from ..splats import cache as splat_cache
from .sources import find_splats, lighting_set, require_splats
from ..common.jobs import Job, gpu, run_now
from ..common.datablocks import is_probe
from ..splats.object import is_splat_object

Progress = Callable[[int, int], None]


def world_box(obj: bpy.types.Object) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the object's bounding box in world space (evaluated: modifiers included)."""
    corners = np.array([list(obj.matrix_world @ Vector(c)) for c in obj.bound_box])
    return corners.min(0), corners.max(0)


def is_lit_mesh(o: bpy.types.Object) -> bool:
    """A rendered mesh that is not splats; shadow catchers and holdouts show no light of their own."""
    return (o.type == "MESH" and not is_splat_object(o) and not o.hide_render
            and not getattr(o, "is_shadow_catcher", False) and not getattr(o, "is_holdout", False))


def lit_meshes(scene: bpy.types.Scene, probe: bpy.types.Object, selected=()) -> list[bpy.types.Object]:
    """The meshes to look at: the selected ones, else every lit mesh (is_lit_mesh) whose bounds centre lies inside
    the probe's splats' bounds (a mesh in the captured room)."""
    mesh = is_lit_mesh
    chosen = [o for o in selected if mesh(o)]
    if chosen:
        return chosen
    splats = find_splats(scene, probe)
    if splats is None:
        return []
    lo, hi = world_box(splats)
    out = []
    for o in scene.objects:
        if mesh(o):
            c = np.mean(world_box(o), axis=0)
            if np.all(c >= lo) and np.all(c <= hi):
                out.append(o)
    return out


def probe_renderer_steps(scene: bpy.types.Scene, probe: bpy.types.Object, need_world: bool = False) -> Job:
    """A job giving the GPU renderer holding the splats that light the probe (its own and the others shown in
    renders: sources.lighting_set; splat_cache), after checking the probe, its splats and, with ``need_world``, that
    it has been baked (local light corrects the light of its World)."""
    if not is_probe(probe):
        raise ValueError(f"{getattr(probe, 'name', None)!r} is not a GS-IBL probe (add one with Add > GS-IBL Probe)")
    splats = require_splats(scene, probe)
    if need_world and probe.gs_ibl_probe.world is None:
        raise ValueError(f"Bake {probe.name!r} first: local light is added to the light of its World")
    return (yield from splat_cache.set_steps(lighting_set(scene, splats))).renderer


def probe_renderer(scene: bpy.types.Scene, probe: bpy.types.Object, need_world: bool = False):
    """probe_renderer_steps, run now."""
    return run_now(probe_renderer_steps(scene, probe, need_world))


def check_variation(scene: bpy.types.Scene, probe: bpy.types.Object, objects: list[bpy.types.Object],
                    progress: Progress | None = None) -> tuple[list[Variation], list[str]]:
    """Probes at each mesh's box centre and corners: (variations, report lines). The lines name the meshes over the
    probe's Variation Tolerance; they are also kept in the probe's local report for the panel."""
    if not objects:
        raise ValueError("No mesh to check: select meshes, or put some inside the splats' bounds")
    r = probe_renderer(scene, probe)
    boxes = {o.name: world_box(o) for o in objects}
    pts = np.concatenate([box_points(*boxes[n]) for n in boxes])
    with gpu:  # the renderer is shared with the overlay and running jobs (blender/jobs.py)
        try:
            sh = bake_sh_points(r, pts, progress=progress)
        finally:
            r.trim(BAKE_KEEP_SHARE)  # the cached renderer keeps a batch's buffers only while small (renderer.py)
    found = [variation_from_sh(n, sh[9 * i:9 * i + 9], pts[9 * i:9 * i + 9]) for i, n in enumerate(boxes)]
    tol = float(probe.gs_ibl_probe.variation_tolerance)
    over = [v for v in found if v.exceeds(tol)]
    lines = [v.message(tol) for v in sorted(found, key=lambda v: -v.variation)]
    lines.insert(0, f"Light variation (tolerance {100 * tol:.0f}%): {len(over)} of {len(found)} meshes over it")
    probe.gs_ibl_probe.local_report = "\n".join(lines)
    return found, lines


def coefficients_with_world(probe: bpy.types.Object, renderer, points: np.ndarray,
                            progress: Progress | None = None,
                            face_size: int = POINT_FACE_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Monomial coefficients of the World probe's light (9, 3) and of probes at ``points`` (P, 9, 3), baked in one
    batch the same way (so their difference carries no difference of method)."""
    pos = np.array(probe.matrix_world.translation, np.float64)
    d = point_coefficients(renderer, np.vstack([pos[None], points]), progress, face_size)
    return d[0], d[1:]


def point_coefficients(renderer, points: np.ndarray, progress: Progress | None = None,
                       face_size: int = POINT_FACE_SIZE) -> np.ndarray:
    """Monomial coefficients (P, 9, 3) of SH probes at ``points``, in one batch; the renderer is trimmed after (as
    check_variation: a batch's buffers stay in the splat cache only while small, renderer.BAKE_KEEP_SHARE)."""
    with gpu:  # the renderer is shared with the overlay and running jobs (blender/jobs.py)
        try:
            return monomial_coefficients(bake_sh_points(renderer, points, face_size, progress=progress))
        finally:
            renderer.trim(BAKE_KEEP_SHARE)


def bake_object_probes(scene: bpy.types.Scene, probe: bpy.types.Object, objects: list[bpy.types.Object],
                       progress: Progress | None = None) -> str:
    """Each mesh its own probe at its bounds centre, through the local-light group; returns the report line."""
    if not objects:
        raise ValueError("No mesh to light: select meshes, or put some inside the splats' bounds")
    r = probe_renderer(scene, probe, need_world=True)
    centres = np.stack([np.mean(world_box(o), axis=0) for o in objects])
    d_world, d = coefficients_with_world(probe, r, centres, progress)
    strength = float(probe.gs_ibl_probe.strength)
    tiles = {}
    for obj, c, di in zip(objects, centres, d):
        key = f"probe:{obj.name}"
        tiles[key] = ll.probe_tile(c, di - d_world)
        ll.set_object_grid(obj, key)
        ll.light_object(obj, strength)
    ll.store_grids(tiles, d_world, probe.gs_ibl_probe.irradiance_image)
    names = ", ".join(o.name for o in objects[:6]) + (", ..." if len(objects) > 6 else "")
    text = (f"Per-object probes for {len(objects)} meshes ({names}), {POINT_FACE_SIZE}x{POINT_FACE_SIZE} faces, "
            "SH order 2")
    probe.gs_ibl_probe.local_report = text
    return text


def remove_local_light(scene: bpy.types.Scene, objects: list[bpy.types.Object]) -> int:
    """Take per-object probes and the grid off ``objects`` (all lit objects of the scene when empty); returns how
    many objects changed."""
    targets = objects or [o for o in scene.objects if ll.has_local_light(o)]
    n = 0
    for obj in targets:
        if ll.has_local_light(obj) or any(ll.in_material(s.material) for s in obj.material_slots):
            ll.unlight_object(obj)
            obj.update_tag()
            n += 1
    return n
