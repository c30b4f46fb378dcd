"""Baking a probe into Blender: probe properties -> core.bake.bake_probe -> images, World, node group.

Used by the Bake operator, by headless scripts (``bpy.ops.gs_ibl.bake_probe()`` or ``bake_into_world``) and by
the "Update When Moved" handler, which re-bakes a probe once after it or its splat object moved and then stayed
still for ``update_interval`` seconds (a depsgraph_update_post handler notes what moved; a timer does the bake).
"""
from __future__ import annotations

import time
from typing import Callable

import bpy
import numpy as np
from bpy.app.handlers import persistent
from mathutils import Vector

from ..core.bake import ProbeSettings, bake_probe, check_fits_device
from ..core.tolerance import plan_text
from ..core.probe.highlights import highlight_text
from ..core.probe.holes import hole_fill_text, hole_warning
from ..core.probe.lights import lights_text
from ..core.probe.near import near_warning
from ..core.probe.latlong import cube_to_latlong
from ..core.settings import method_from_blender
from . import splat_cache
from .bake_undo import stamp
from . import world as gw
from .lights_from_probe import sync_lights
from .properties import is_probe
from .jobs import Job, Step, Work, busy, cancel_all, run_now
from .jobs import start as start_job
from .splat_object import is_splat_object, splat_count

HOLE_WARNING = 0.01  # warn when more of the sphere than this sees no splat
WARNING_PREFIX = "Warning: "  # a report line the panel shows with a warning icon


def probe_settings(props) -> ProbeSettings:
    """The core's settings from a probe's properties (Object.gs_ibl_probe)."""
    return ProbeSettings(method=method_from_blender(props.method), face_size=int(props.face_size),
                         irradiance_size=int(props.irradiance_size), tolerance=float(props.tolerance),
                         highlight_gain=float(props.highlight_gain), lights=int(props.lights))


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


def result_latlong(result, kind: str, height: int) -> np.ndarray:
    """(height, 2*height, 3) lat-long of a ProbeResult's ``kind`` cube ("radiance" or "irradiance")."""
    cube = np.asarray(getattr(result, kind), np.float32)[..., :3]
    return cube_to_latlong(cube, 2 * height, height)


def _own(probe: bpy.types.Object, attr: str):
    """The datablock the probe's last bake wrote (``attr`` of its settings), unless another probe refers to it
    too (a duplicated probe copies the references): then None, so this probe gets its own."""
    idb = getattr(probe.gs_ibl_probe, attr)
    if idb is None:
        return None
    shared = any(o != probe and is_probe(o) and getattr(o.gs_ibl_probe, attr) == idb for o in bpy.data.objects)
    return None if shared else idb


def apply_probe_images(scene: bpy.types.Scene, probe: bpy.types.Object, radiance: np.ndarray,
                       irradiance: np.ndarray | None) -> bpy.types.World:
    """Write baked lat-long maps into the probe's images and World and the irradiance node group, per the probe's
    settings. Files (Pack Images off) are named gs_ibl_<probe>_<role>.exr."""
    s = probe.gs_ibl_probe
    stem = f"gs_ibl_{probe.name}"
    s.radiance_image = gw.latlong_image("radiance", radiance, pack=s.pack_images, image=_own(probe, "radiance_image"),
                                        file_stem=f"{stem}_radiance")
    if irradiance is not None:
        s.irradiance_image = gw.latlong_image("irradiance", irradiance, pack=s.pack_images,
                                              image=_own(probe, "irradiance_image"), file_stem=f"{stem}_irradiance")
        gw.irradiance_group(s.irradiance_image)
    # The camera keeps what it saw before we first took over the World.
    previous = scene.get(gw.PREVIOUS_WORLD)
    if not isinstance(previous, bpy.types.World):
        previous = scene.world if scene.world is not None and scene.world.get(gw.MARKER) != "world" else None
    s.world = gw.build_world(s.radiance_image, s.strength, s.keep_background, previous, replace=_own(probe, "world"))
    if s.assign_world:
        gw.use_world(scene, s.world)
        if s.mute_native_splats:
            gw.mute_native_splats(scene)
        else:
            gw.unmute_native_splats(scene)
    return s.world


FILTER_STAGES = ("sh_project", "irradiance", "ggx")  # the filters a bake runs; their other keys are details


def filter_gpu_ms(timings: dict[str, float]) -> float:
    """The filters' GPU time of a bake: SH projection + irradiance (+ GGX when baked).

    Only these totals: ``<stage>_wall`` (the same work timed on the host), ``<stage>.<step>`` (the per-step split of
    the total) and ``upload`` would count time twice or time the host. Where a stage ran on the CPU its value is
    wall time (core/probe/filters.py).
    """
    return sum(timings.get(k, 0.0) for k in FILTER_STAGES)


def summary(result, seconds: float, stages: dict[str, float] | None = None) -> tuple[list[str], str | None]:
    """(lines saying what the bake did and how long each part took, hole warning or None). ``stages``: wall
    seconds of the bake's parts, in order (reading, turning SH and upload when this bake made the splats' GPU copy;
    bake; writing; each mesh's light); with "other" (what they leave of ``seconds``) they add up to it."""
    t = result.timings_ms
    render_ms = t.get("render_total", sum(v for k, v in t.items() if k.startswith("render_")))
    filter_ms = filter_gpu_ms(t)
    st = result.settings
    method = st.get("method", "?")
    how = f"method {method}"
    trials = [t for t in st.get("face_size_trials", []) if t.get("change") is not None]
    if trials:
        steps = ", ".join(f"{'/'.join(map(str, t.get('face_sizes') or [t['face_size']]))}: {100 * t['change']:.2f}%"
                          for t in trials)  # per-face sizes: +X/-X/+Y/-Y/+Z/-Z
        verdict = "converged" if st.get("converged") else "NOT converged at the size limit"
        how = f"{method}; face size by irradiance change ({steps}) {verdict}"
    face = st.get("face_size", np.asarray(result.radiance).shape[1])
    timing = f"render {render_ms:.0f} ms, filter {filter_ms:.0f} ms, total {seconds:.2f} s ({result.device})"
    if stages:
        parts = {**stages, "other": max(seconds - sum(stages.values()), 0.0)}
        timing += "; the total: " + ", ".join(f"{k} {v:.2f} s" for k, v in parts.items())
    lines = [f"Baked {result.splat_count:,} splats, {face}x{face} faces", how, timing]
    lines.append(hole_fill_text(result.hole_fill))
    if plan_text(st):  # what the tolerance chose and the estimated error (core/tolerance.py)
        lines.append(plan_text(st))
    lines += [line for line in (highlight_text(result.highlights), lights_text(result.lights)) if line]
    warning = None
    if result.hole_fraction > HOLE_WARNING:
        warning = hole_warning(result.hole_fill) or (f"the probe sees holes: {100 * result.hole_fraction:.1f}% of "
                                                     "directions have no splat")
    near = near_warning(result.near_splats)  # only where the bake had the splats on the host
    if near:
        warning = f"{warning}; {near}" if warning else near
    return lines, warning


def bake_into_world(scene: bpy.types.Scene, probe: bpy.types.Object, splats: bpy.types.Object | None = None,
                    progress: Callable[[str, float], None] | None = None):
    """Bake ``probe`` from ``splats`` (default: the probe's) and write the result into Blender, now (bake_job run
    in this thread). Returns (ProbeResult, one-line report, hole warning or None). Raises ValueError/RuntimeError/
    OSError/MemoryError with a message meant for the user."""
    return run_now(bake_job(scene, probe, splats), progress)


def bake_job(scene: bpy.types.Scene, probe: bpy.types.Object, splats: bpy.types.Object | None = None) -> Job:
    """The bake as a job (blender/jobs.py): checked now, before any work (a ValueError says what is wrong); then
    the splats read a piece at a time on the main thread, turned, uploaded and baked by a worker, and written into
    Blender on the main thread at the end. Its result: (ProbeResult, one-line report, hole warning or None)."""
    if not is_probe(probe):
        raise ValueError(f"{getattr(probe, 'name', None)!r} is not a GS-IBL probe (add one with Add > GS-IBL Probe)")
    splats = splats or require_splats(scene, probe)
    if not in_scene(scene, splats):
        raise ValueError(f"{splats.name!r} is not in scene {scene.name!r}: a deleted or unlinked splat object is "
                         "never baked")
    settings = probe_settings(probe.gs_ibl_probe)
    check_fits_device(settings)  # before reading or uploading anything (limits.TooBig, a ValueError, names the size)
    return _bake_steps(scene.name, probe.name, splats, settings)


def _named(scene_name: str, probe_name: str, splats_name: str):
    """The scene, probe and splat object by name, after a worker ran: the user may have deleted them meanwhile (a
    Runner's job keeps the UI working), and a reference held across that would point at freed data."""
    scene = bpy.data.scenes.get(scene_name)
    probe = scene.objects.get(probe_name) if scene is not None else None
    splats = scene.objects.get(splats_name) if scene is not None else None
    if probe is None or not is_probe(probe) or splats is None:
        gone = probe_name if probe is None or not is_probe(probe) else splats_name
        raise ValueError(f"{gone!r} was deleted while it was being baked: nothing was written")
    return scene, probe, splats


def _bake_and_resample(where: np.ndarray, settings: ProbeSettings, cached, local=None,
                       progress: Callable[[str, float], None] | None = None):
    """The worker's part of a bake: the core bake and its lat-long images. ``local``: (splats as read, matrix,
    object name) for a bake that uploads its own copy."""
    if local is not None:  # the gain goes on the splats (exact), so this bake uploads its own copy
        from .splat_object import to_world
        result = bake_probe(to_world(*local), where, settings, progress=progress)
    else:
        result = bake_probe(None, where, settings, renderer=cached.renderer, progress=progress,
                            host_splats=cached.host)
    face = np.asarray(result.radiance).shape[1]
    irr_face = np.asarray(result.irradiance).shape[1]
    # lat-long width >= 4x the face size keeps the resampling from aliasing (core/probe/latlong.py)
    radiance = result_latlong(result, "radiance", max(2 * face, 32))
    irradiance = result_latlong(result, "irradiance", max(2 * irr_face, 32))
    return result, radiance, irradiance


def _bake_steps(scene_name: str, probe_name: str, splats: bpy.types.Object, settings: ProbeSettings) -> Job:
    t0 = time.perf_counter()
    stages: dict[str, float] = {}  # wall seconds of the report's parts (they add up to its total)

    def lap(name: str, since: float) -> float:
        now = time.perf_counter()
        stages[name] = stages.get(name, 0.0) + now - since
        return now

    splats_name = splats.name
    yield Step(f"reading {splat_count(splats):,} splats", 0.0)
    uploads = splat_cache.uploads
    cached = yield from splat_cache.get_steps(splats)  # read and uploaded once, shared with the overlay and re-bakes
    if splat_cache.uploads != uploads:  # this bake read them: reading, turning SH, upload (a wait is "other")
        stages.update(cached.timings)
    t = time.perf_counter()
    scene, probe, splats = _named(scene_name, probe_name, splats_name)
    check_fits_device(settings, cached.renderer.ctx, cached.renderer.scene_count)
    where = np.array(probe.matrix_world.translation, np.float64)
    local = None
    if settings.highlight_gain != 1:
        from .splat_object import read_steps
        local = (*(yield from read_steps(splats)), splats_name)
    result, radiance, irradiance = yield Work(_bake_and_resample, where, settings, cached, local, span=(0.05, 0.95))
    t = lap("bake", t)  # renders, filters and the host work between them
    scene, probe, splats = _named(scene_name, probe_name, splats_name)
    yield Step("writing the light into Blender", 0.95)
    apply_probe_images(scene, probe, radiance, irradiance)
    sync_lights(scene, probe, result.lights, probe.gs_ibl_probe.strength)
    t = lap("writing", t)
    if probe.gs_ibl_probe.splats is None:
        probe.gs_ibl_probe.splats = splats  # the field says what was baked (and what Update When Moved follows)
    _baked[(scene.name, probe.name)] = bake_state(probe, splats)
    auto = None
    if probe.gs_ibl_probe.lighting == "AUTO":
        yield Step("choosing each mesh's light", 0.96)
        auto = yield from _relight_steps(scene, probe)
        scene, probe, splats = _named(scene_name, probe_name, splats_name)
        t = lap("each mesh's light", t)
    else:
        from .auto_light import remove_auto_light  # imports object_probes, which imports this module
        remove_auto_light(scene, probe)  # World Probe: the World alone, for meshes Auto lit before too
    lines, warning = summary(result, time.perf_counter() - t0, stages)
    if auto:
        lines.append(auto)
    probe.gs_ibl_probe.last_report = "\n".join(lines + ([WARNING_PREFIX + warning] if warning else []))
    stamp(probe)
    return result, ", ".join(lines), warning


# ---------------------------------------------------------------------------------------------- update when moved

_pending: set[tuple[str, str]] = set()  # (scene name, probe name) waiting for a re-bake
_pending_meshes: dict[tuple[str, str], set[str]] = {}  # (scene, probe) -> lit meshes that moved (Lighting Auto)
_lit_places: dict[tuple[str, str], dict[str, bytes]] = {}  # (scene, probe) -> {mesh: its matrix when its light
# was chosen}
auto_relights = 0  # automatic re-choices of moved meshes' light (tests see how often a move re-lit)
_baked: dict[tuple[str, str], tuple] = {}  # (scene name, probe name) -> bake_state() of its last bake
last_auto_error: str | None = None  # the last automatic bake's error, for the panel and tests
auto_bakes = 0  # automatic bakes run so far (tests and the console see how often a move re-baked)
_rebaseline_next = False  # an undo or redo happened: the next depsgraph update is not a move


def bake_state(probe: bpy.types.Object, splats: bpy.types.Object | None) -> tuple:
    """What a bake's light depends on that a move changes: the probe's position and the splats' placement and data.

    A re-bake is due only when this differs from the last bake's: depsgraph updates also report objects whose
    transform did not change (a bake writing the probe's own properties is one), which once made every bake
    schedule the next."""
    return (tuple(round(float(c), 9) for c in probe.matrix_world.translation),
            splat_cache.data_key(splats) if splats is not None else None)


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


def _place(obj: bpy.types.Object) -> bytes:
    return np.array(obj.matrix_world, np.float64).round(9).tobytes()


def _relight_steps(scene: bpy.types.Scene, probe: bpy.types.Object, meshes: list | None = None) -> Job:
    """Lighting Auto as a job: choose the light of ``meshes`` (default: every lit mesh) and remember where they
    were."""
    from .auto_light import auto_light_steps  # imports object_probes, which imports this module
    scene_name, probe_name = scene.name, probe.name
    text, choices = yield from auto_light_steps(scene, probe, meshes)
    scene = bpy.data.scenes[scene_name]  # auto_light_steps found it after its workers
    places = _lit_places.setdefault((scene_name, probe_name), {})
    for c in choices:
        obj = scene.objects.get(c.name)
        if obj is not None:
            places[c.name] = _place(obj)
    return text


def _moved_lit_meshes(scene: bpy.types.Scene, probe: bpy.types.Object, moved: set[str]) -> set[str]:
    """The meshes among ``moved`` whose light a Lighting Auto probe should choose again."""
    from .object_probes import is_lit_mesh  # imports this module
    if probe.gs_ibl_probe.lighting != "AUTO":
        return set()
    places = _lit_places.get((scene.name, probe.name), {})
    out = set()
    for name in moved:
        obj = scene.objects.get(name)
        if obj is None or not is_lit_mesh(obj) or places.get(name) == _place(obj):
            continue
        out.add(name)
    return out


def rebaseline_after_undo() -> None:
    """After an undo or redo, which brings back the probe, its World and their report together, nothing has moved
    since their bake: waiting re-bakes are dropped, and the next depsgraph update (when the restored objects'
    world matrices are evaluated; in undo_post they are not yet) takes every state as baked."""
    global _rebaseline_next
    _pending.clear()
    if bpy.app.timers.is_registered(run_pending):
        bpy.app.timers.unregister(run_pending)
    _rebaseline_next = True


def _rebaseline() -> None:
    _pending_meshes.clear()
    for scene in bpy.data.scenes:
        for obj in scene.objects:
            if is_probe(obj) and obj.gs_ibl_probe.auto_update:
                _baked[(scene.name, obj.name)] = bake_state(obj, auto_splats(scene, obj))
                places = _lit_places.get((scene.name, obj.name), {})
                for name in places:
                    mesh = scene.objects.get(name)
                    if mesh is not None:
                        places[name] = _place(mesh)


def _moved_names(depsgraph) -> set[str]:
    return {u.id.original.name for u in depsgraph.updates
            if u.is_updated_transform and isinstance(u.id, bpy.types.Object)}


@persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """Notes auto-updating probes whose probe or splat object really moved and (re)starts one debounce timer: the
    re-bake runs once the objects have stayed still for the probe's Update Delay, so a drag bakes once."""
    global _rebaseline_next
    clear_lost_splats(scene)
    if _rebaseline_next:
        _rebaseline_next = False
        _rebaseline()
        return
    moved = _moved_names(depsgraph)
    if not moved:
        return
    delay = None
    for obj in scene.objects:
        if not is_probe(obj) or not obj.gs_ibl_probe.auto_update:
            continue
        splats = auto_splats(scene, obj)
        if splats is None:
            continue
        key = (scene.name, obj.name)
        meshes = _moved_lit_meshes(scene, obj, moved)
        if meshes:
            _pending_meshes.setdefault(key, set()).update(meshes)
        # a probe parented to a mesh ("follows" it) is reported moved with it
        if (obj.name not in moved and splats.name not in moved) or bake_state(obj, splats) == _baked.get(key):
            if not meshes:
                continue
        else:
            _pending.add(key)
        d = obj.gs_ibl_probe.update_interval
        delay = d if delay is None else min(delay, d)
    if delay is not None:
        if bpy.app.timers.is_registered(run_pending):
            bpy.app.timers.unregister(run_pending)  # still moving: start the wait again
        bpy.app.timers.register(run_pending, first_interval=delay)


UPDATE_JOB = "update when moved"  # the background job (blender/jobs.py) of automatic re-bakes


def run_pending() -> float | None:
    """Timer: re-bake every probe noted by on_depsgraph_update whose state still differs from its last bake, as a
    background job (the window stays responsive; without one, as in ``blender -b``, now). While an earlier one
    runs it waits for it (returns the timer's next interval). Errors go to the console and the probe's report."""
    if busy(UPDATE_JOB):
        return 0.25
    keys = sorted(_pending | set(_pending_meshes))
    relight = {k: _pending_meshes.pop(k) for k in list(_pending_meshes)}
    _pending.clear()
    if keys:
        start_job(UPDATE_JOB, _pending_job(keys, relight), "re-baking moved probes", done=_update_done)
    return None  # one-shot; the handler registers it again when something moves


def _update_done(runner) -> None:
    global last_auto_error
    if runner.error is not None:  # the job catches the users' errors itself: this is a bug, said once
        last_auto_error = f"{type(runner.error).__name__}: {runner.error}"
        print(f"GS-IBL (update when moved): {last_auto_error}")
    from .overlay import tag_redraw
    tag_redraw()


def _pending_job(keys: list[tuple[str, str]], relight: dict[tuple[str, str], set[str]]) -> Job:
    global last_auto_error, auto_bakes, auto_relights
    for scene_name, probe_name in keys:
        scene = bpy.data.scenes.get(scene_name)
        probe = scene.objects.get(probe_name) if scene is not None else None
        if probe is None or not is_probe(probe):
            continue
        splats = auto_splats(scene, probe)
        if splats is None:
            continue
        if bake_state(probe, splats) == _baked.get((scene_name, probe_name)):
            meshes = [scene.objects[n] for n in sorted(relight.get((scene_name, probe_name), ()))
                      if n in scene.objects and probe.gs_ibl_probe.world is not None]
            if meshes:  # only lit meshes moved: their light is chosen again, the World stays
                try:
                    auto_relights += 1
                    text = yield from _relight_steps(scene, probe, meshes)
                    print(f"GS-IBL (update when moved): {text}")
                except (ValueError, RuntimeError, OSError, MemoryError) as e:
                    last_auto_error = f"{probe_name}: {e}"
                    print(f"GS-IBL (update when moved): {last_auto_error}")
            continue  # the probe moved back to where it was baked, or only meshes moved
        try:
            auto_bakes += 1
            _, text, warning = yield from bake_job(scene, probe, splats)
            last_auto_error = None
            print(f"GS-IBL (update when moved): {text}" + (f"; WARNING: {warning}" if warning else ""))
        except (ValueError, RuntimeError, OSError, MemoryError) as e:
            last_auto_error = f"{probe_name}: {e}"
            scene = bpy.data.scenes.get(scene_name)
            probe = scene.objects.get(probe_name) if scene is not None else None
            if probe is not None and is_probe(probe):
                probe.gs_ibl_probe.last_report = f"{WARNING_PREFIX}automatic re-bake failed:\n{e}"
            print(f"GS-IBL (update when moved): {last_auto_error}")


@persistent
def on_load_pre(*_args) -> None:
    global _rebaseline_next
    cancel_all()  # their results would land in the file being closed
    _rebaseline_next = False
    _pending.clear()
    _pending_meshes.clear()
    _lit_places.clear()
    _baked.clear()  # names of another file's probes


def register_handlers() -> None:
    if on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)
    if on_load_pre not in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.append(on_load_pre)


def unregister_handlers() -> None:
    while on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(on_depsgraph_update)
    while on_load_pre in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(on_load_pre)
    if bpy.app.timers.is_registered(run_pending):
        bpy.app.timers.unregister(run_pending)
    on_load_pre()
