"""Is a probe's bake out of date? What each bake was made from is kept on the probe (an ID property, so it is saved
with the file and Undo brings it back together with the report it belongs to); the panel and the status bar compare
it with the scene as it is now.

Out of date: the probe moved, its splat object moved, was edited (its splat count changed) or replaced, its Lighting
(Auto / Volume / World Probe) changed, or, for Lighting Auto, a mesh it chose the light of moved. After an undo that
brought back an earlier bake's report while the probe stayed where the later bake was made, the mark shows too: the
report and the World describe the probe where it was then.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..common.jobs import set_notice
from ..splats.object import splat_count
from .sources import lighting_set

BAKED_KEY = "gs_ibl_baked"  # on a probe: {"probe": xyz, "splats": name, "splats_matrix": 16 floats,
# "splats_count": n, "meshes": {name: 16 floats}, "lighting": "AUTO" | "VOLUME" | "WORLD", "volume_probes": n} of its
# last bake
NOTICE = "stale"  # the status bar's line (common/jobs.py set_notice)
_TOLERANCE = 1e-5  # metres (and matrix entries): float32 round trips and re-evaluation are far below
_NAMED = 3  # meshes named at most in a reason
_baking: set[tuple[str, str]] = set()  # (scene, probe) names whose bake job runs now


def while_baking(scene_name: str, probe_name: str, job):
    """``job`` (a bake of the probe), during which the probe's bake is not marked out of date: the status bar
    showed the mark beside the progress of the bake that was making it good."""
    _baking.add((scene_name, probe_name))
    try:
        return (yield from job)
    finally:  # also when it fails or is cancelled (the generator is closed)
        _baking.discard((scene_name, probe_name))


def _matrix(obj: bpy.types.Object) -> list[float]:
    return [float(v) for row in obj.matrix_world for v in row]


def _differs(a, b) -> bool:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape != b.shape or not np.allclose(a, b, rtol=0.0, atol=_TOLERANCE)


def record_bake(probe: bpy.types.Object, splats: bpy.types.Object, others=()) -> None:
    """What the bake just written was made from: the probe's place, its ``splats`` and the ``others`` that lit it
    with them (sources.lighting_set) (Lighting Auto's meshes are added by record_meshes)."""
    probe[BAKED_KEY] = {"probe": [float(v) for v in probe.matrix_world.translation], "splats": splats.name,
                        "splats_matrix": _matrix(splats), "splats_count": splat_count(splats), "meshes": {},
                        "others": {o.name: {"matrix": _matrix(o), "count": splat_count(o)} for o in others},
                        "lighting": probe.gs_ibl_probe.lighting, "volume_probes": probe.gs_ibl_probe.volume_probes}


def record_meshes(scene: bpy.types.Scene, probe: bpy.types.Object, names) -> None:
    """Where the meshes whose light Lighting Auto just chose are."""
    rec = probe.get(BAKED_KEY)
    if rec is None:
        return
    meshes = dict(rec.get("meshes", {}))
    for name in names:
        obj = scene.objects.get(name)
        if obj is not None:
            meshes[name] = _matrix(obj)
    rec["meshes"] = meshes


def _animated(obj: bpy.types.Object) -> bool:
    ad = obj.animation_data
    return ad is not None and (ad.action is not None or len(ad.drivers) > 0)


def animated_follow(probe: bpy.types.Object) -> bpy.types.Object | None:
    """The probe itself or the nearest parent it follows whose animation moves it (None: none): its bake holds the
    light where that one stood at the frame of the bake, not along its path."""
    obj = probe
    while obj is not None:
        if _animated(obj):
            return obj
        obj = obj.parent
    return None


def animated_text(probe: bpy.types.Object, frame: int | None = None) -> str | None:
    """What the panel and the bake report say about an animated probe (None: not animated); ``frame``: the bake's."""
    moving = animated_follow(probe)
    if moving is None:
        return None
    who = "the probe is animated" if moving is probe else f"the probe follows {moving.name}, which is animated"
    return f"{who}: baked at frame {frame}" if frame is not None else f"{who}: each bake holds the light where it " \
                                                                       "stands at the current frame"


def stale_reasons(scene: bpy.types.Scene, probe: bpy.types.Object, meshes: bool = True) -> list[str]:
    """Why the probe's last bake no longer describes the scene (empty: it does, the probe has no record: never
    baked, or baked by a version before the record, or its bake runs now). ``meshes`` False: not Lighting Auto's
    meshes that moved (what Update When Moved relights without a bake)."""
    rec = probe.get(BAKED_KEY)
    if rec is None or not probe.gs_ibl_probe.last_report or (scene.name, probe.name) in _baking:
        return []
    out = []
    if _differs(probe.matrix_world.translation, rec.get("probe", ())):
        out.append("the probe moved")
    name = str(rec.get("splats", ""))
    splats = scene.objects.get(name)
    chosen = probe.gs_ibl_probe.splats
    if chosen is not None and splats is None and not _differs(_matrix(chosen), rec.get("splats_matrix", ())) \
            and splat_count(chosen) == rec.get("splats_count"):
        splats, name = chosen, chosen.name  # renamed since: the same splats
    if chosen is not None and chosen.name != name:
        out.append(f"its Splats is now {chosen.name!r}")
    elif splats is None:
        out.append(f"its splats {name!r} are no longer in the scene")
    elif _differs(_matrix(splats), rec.get("splats_matrix", ())):
        out.append(f"{name!r} moved")
    elif splat_count(splats) != rec.get("splats_count"):
        out.append(f"{name!r} was edited")
    if splats is not None and "others" in rec:  # (a record from before several objects lit a probe: no mark)
        out += _others_reasons(scene, splats, rec["others"])
    lighting = probe.gs_ibl_probe.lighting
    if rec.get("lighting", lighting) != lighting:  # a record from before it was kept: no mark
        out.append(f"its Lighting is now {probe.gs_ibl_probe.bl_rna.properties['lighting'].enum_items[lighting].name}")
    elif lighting == "VOLUME" and rec.get("volume_probes", probe.gs_ibl_probe.volume_probes) != \
            probe.gs_ibl_probe.volume_probes:
        out.append(f"its Volume Probes is now {probe.gs_ibl_probe.volume_probes}")
    moved = [m for m, place in rec.get("meshes", {}).items()
             if meshes and m in scene.objects and _differs(_matrix(scene.objects[m]), place)]
    if moved:
        names = ", ".join(repr(m) for m in moved[:_NAMED]) + (f" and {len(moved) - _NAMED} more"
                                                               if len(moved) > _NAMED else "")
        out.append(f"{names} moved" if len(moved) == 1 else f"lit meshes {names} moved")
    return out


def _others_reasons(scene: bpy.types.Scene, splats: bpy.types.Object, recorded) -> list[str]:
    """How the other splat objects that light the probe differ from those its bake recorded."""
    now = {o.name: o for o in lighting_set(scene, splats)[1:]}
    out = [f"{n!r} now lights it" for n in now if n not in recorded]
    out += [f"{n!r} no longer lights it" for n in recorded if n not in now]
    for n, o in now.items():
        if n in recorded and _differs(_matrix(o), recorded[n].get("matrix", ())):
            out.append(f"{n!r} moved")
        elif n in recorded and splat_count(o) != recorded[n].get("count"):
            out.append(f"{n!r} was edited")
    return out


def stale_text(reasons: list[str]) -> str:
    """The mark the panel shows over the report."""
    return f"Out of date since this bake ({'; '.join(reasons)}): Bake / Refresh"


def refresh_notice(scene: bpy.types.Scene) -> str | None:
    """The status bar's line about out-of-date bakes of ``scene``'s probes (None: none); shown by common/jobs.py
    beside the running jobs, and cleared when they are up to date again."""
    stale = [(obj.name, reasons) for obj in scene.objects
             if obj.type == "EMPTY" and getattr(obj.gs_ibl_probe, "is_probe", False)
             for reasons in [stale_reasons(scene, obj)] if reasons]
    if not stale:
        text = None
    elif len(stale) == 1:
        text = f"GS-IBL: the bake of {stale[0][0]!r} is out of date ({'; '.join(stale[0][1])}): Bake / Refresh"
    else:
        text = (f"GS-IBL: the bakes of {len(stale)} probes are out of date "
                f"({', '.join(repr(n) for n, _ in stale)}): Bake / Refresh")
    set_notice(NOTICE, text)
    return text
