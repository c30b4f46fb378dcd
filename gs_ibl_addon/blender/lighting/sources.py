"""Which splat objects light a probe: its own (the probe's Splats field, else the active or the scene's only one),
and with it every other splat object of the scene shown in renders (a room and a capture standing in it light the
meshes together, sorted as one scene): its camera icon on and in the view layer, as F12 takes them."""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Vector

from ..common.datablocks import is_probe
from ..splats.object import current_layer, in_view_layer, is_splat_object


def scene_splats(scene: bpy.types.Scene) -> list[bpy.types.Object]:
    return [o for o in scene.objects if is_splat_object(o)]


def in_scene(scene: bpy.types.Scene, obj: bpy.types.Object | None) -> bool:
    """Whether ``obj`` is one of the scene's objects: a deleted object lives on (unlinked) while a pointer such as
    a probe's Splats field still refers to it."""
    return obj is not None and scene.objects.get(obj.name) == obj


def require_splats(scene: bpy.types.Scene, probe: bpy.types.Object | None = None,
                   active: bpy.types.Object | None = None) -> bpy.types.Object:
    """The splat object a bake of ``probe`` reads: the probe's Splats field, else the active splat object, else the
    scene's only one. Raises ValueError saying what is wrong and what to do."""
    chosen = probe.gs_ibl_probe.splats if probe is not None else None
    if chosen is not None:
        if not in_scene(scene, chosen):
            raise ValueError(f"{probe.name}: its splat object {chosen.name!r} is no longer in the scene (deleted or "
                             "unlinked): pick another in the probe's Splats field")
        return chosen
    if is_splat_object(active) and in_scene(scene, active):
        return active
    found = scene_splats(scene)
    if len(found) == 1:
        return found[0]
    if not found:
        raise ValueError("No splat object in the scene: import a splat file (File > Import > Gaussian Splatting)")
    names = ", ".join(repr(o.name) for o in found[:4]) + (", ..." if len(found) > 4 else "")
    raise ValueError(f"{len(found)} splat objects in the scene ({names}): pick one in the probe's Splats field")


def lighting_set(scene: bpy.types.Scene, own: bpy.types.Object) -> list[bpy.types.Object]:
    """The splat objects that light a probe whose own is ``own``: it first, then every other one of the scene not
    hidden from renders and in the user's view layer (a collection it excludes is not rendered), in the scene's order
    (merged as F12 draws them: core.scene.combine_scenes)."""
    layer = current_layer(scene)
    return [own] + [o for o in scene_splats(scene)
                    if o != own and not o.hide_render and in_view_layer(o, layer)]


def set_line(names: list[str]) -> str | None:
    """What a bake's report says of the splat objects ``names`` that lit it (the probe's own first); None when one
    lit it alone."""
    if len(names) < 2:
        return None
    return f"from {len(names)} splat objects: " + ", ".join(names[:6]) + (", ..." if len(names) > 6 else "")


def find_splats(scene: bpy.types.Scene, probe: bpy.types.Object | None = None,
                active: bpy.types.Object | None = None) -> bpy.types.Object | None:
    """require_splats, or None where it would refuse."""
    try:
        return require_splats(scene, probe, active)
    except ValueError:
        return None


def enclosing_splats(scene: bpy.types.Scene, point) -> bpy.types.Object | None:
    """The scene's only splat object, or of several the largest whose world bounds hold ``point`` (the room a
    probe stands in, not a small capture inside it); None when none does."""
    found = scene_splats(scene)
    if len(found) == 1:
        return found[0]
    p = np.asarray(point, np.float64)
    best, best_volume = None, -1.0
    for o in found:
        corners = np.array([list(o.matrix_world @ Vector(c)) for c in o.bound_box])
        lo, hi = corners.min(0), corners.max(0)
        volume = float(np.prod(hi - lo))
        if np.all(p >= lo) and np.all(p <= hi) and volume > best_volume:
            best, best_volume = o, volume
    return best


def auto_splats(scene: bpy.types.Scene, probe: bpy.types.Object) -> bpy.types.Object | None:
    """The splat object an automatic re-bake reads: only the probe's own Splats field, and only while that object
    is in the scene (never a guess: a deleted room must not hand the probe to another capture)."""
    splats = probe.gs_ibl_probe.splats
    return splats if in_scene(scene, splats) else None


def clear_lost_splats(scene: bpy.types.Scene) -> None:
    """Empty the Splats field of the scene's probes whose splat object is in no scene any more (deleted or
    unlinked: the pointer alone would keep it alive and baked). Undo brings the object and the field back."""
    for obj in scene.objects:
        if is_probe(obj):
            splats = obj.gs_ibl_probe.splats
            if splats is not None and not splats.users_scene:
                obj.gs_ibl_probe.splats = None
