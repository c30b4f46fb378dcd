"""Update When Moved: a probe re-baked once after it or its splat object moved and then stayed still for its
``update_interval`` seconds (a depsgraph_update_post handler notes what moved; a timer does the bake), a Lighting
Auto probe's meshes given their light again when only they moved, and a Lighting Volume probe's volume grown over a
lit mesh that left it (only the new part rendered: volume.py, core/probe/volume_refine.py extend_volume)."""
from __future__ import annotations

import time

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..common import handlers
from ..common.datablocks import is_probe
from ..common.jobs import Job, busy, cancel_all, within
from ..common.jobs import start as start_job
from ..common.redraw import tag_redraw
from .bake import (WARNING_PREFIX, bake_job, bake_state, baked_states, lit_places, place_key, relight_steps,
                   seen_states)
from .object_probes import is_lit_mesh, world_box
from .sources import auto_splats, clear_lost_splats
from .auto_light import REPORT_PREFIX as AUTO_PREFIX
from .stale import BAKED_KEY, refresh_notice, stale_reasons
from .volume import REPORT_PREFIX as VOLUME_PREFIX
from .volume import forget_volumes, kept_volume, volume_light_steps

_pending: set[tuple[str, str]] = set()  # (scene name, probe name) waiting for a re-bake
_pending_meshes: dict[tuple[str, str], set[str]] = {}  # (scene, probe) -> lit meshes that moved (Auto, Volume)
auto_relights = 0  # automatic re-choices of moved meshes' light (tests see how often a move re-lit)
last_auto_error: str | None = None  # the last automatic bake's error, for the panel and tests
auto_bakes = 0  # automatic bakes run so far (tests and the console see how often a move re-baked)
_rebaseline_next = False  # an undo or redo happened: the next depsgraph update is not a move
_adopt_saved_next = False  # a file was opened: its next depsgraph update takes its up-to-date bakes as baked
AUTO_MOVED = "Auto lighting after the last move: "  # Details' line for Lighting Auto's relights
MOVED_SUMMARY = "; after a move: "  # the panel's line after a relight or growth: "...; after a move: ... in N s"


def _moved_lit_meshes(scene: bpy.types.Scene, probe: bpy.types.Object, moved: set[str]) -> set[str]:
    """The meshes among ``moved`` whose light a Lighting Auto probe should choose again, or that left a Lighting
    Volume probe's volume (inside it a mesh is lit where it stands: nothing to do)."""
    if probe.gs_ibl_probe.lighting == "VOLUME":
        vol = kept_volume(scene, probe)
        if vol is None:
            return set()
        lo, hi = np.asarray(vol.spec.lo) - 1e-6, np.asarray(vol.spec.hi) + 1e-6
        out = set()
        for name in moved:
            obj = scene.objects.get(name)
            if obj is not None and is_lit_mesh(obj):
                blo, bhi = world_box(obj)
                if np.any(blo < lo) or np.any(bhi > hi):
                    out.add(name)
        return out
    if probe.gs_ibl_probe.lighting != "AUTO":
        return set()
    places = lit_places.get((scene.name, probe.name), {})
    out = set()
    for name in moved:
        obj = scene.objects.get(name)
        if obj is None or not is_lit_mesh(obj) or places.get(name) == place_key(obj):
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
                baked_states[(scene.name, obj.name)] = seen_states[(scene.name, obj.name)] = \
                    bake_state(obj, auto_splats(scene, obj), scene)
                places = lit_places.get((scene.name, obj.name), {})
                for name in places:
                    mesh = scene.objects.get(name)
                    if mesh is not None:
                        places[name] = place_key(mesh)


def _adopt_saved(scene: bpy.types.Scene) -> None:
    """A bake saved up to date (its record on the probe matches the scene: stale.py; Lighting Auto's meshes may have
    moved, which a relight follows) was made from the state seen now: a lit mesh moved after opening the file is
    relit (the volume grown) without baking the World again. Asked at the first depsgraph update after opening (at
    load_post the objects' matrices may not be evaluated yet), which may be that move's."""
    for obj in scene.objects:
        if is_probe(obj) and obj.get(BAKED_KEY) is not None and not stale_reasons(scene, obj, meshes=False):
            splats = auto_splats(scene, obj)
            if splats is not None:
                baked_states[(scene.name, obj.name)] = bake_state(obj, splats, scene)


def _probe_named(scene_name: str, probe_name: str) -> bpy.types.Object | None:
    """The object of that name in the scene of that name, if both are still there (a job's names outlive them)."""
    scene = bpy.data.scenes.get(scene_name)
    return scene.objects.get(probe_name) if scene is not None else None


def _replace_line(scene_name: str, probe_name: str, prefix: str, text: str) -> None:
    """The probe's report (Details) with its line starting ``prefix`` replaced by ``text`` (added if it has none)."""
    probe = _probe_named(scene_name, probe_name)
    if probe is None:
        return
    lines = probe.gs_ibl_probe.last_report.split("\n") if probe.gs_ibl_probe.last_report else []
    at = next((i for i, line in enumerate(lines) if line.startswith(prefix)), None)
    if at is None:
        lines.append(text)
    else:
        lines[at] = text
    probe.gs_ibl_probe.last_report = "\n".join(lines)


def _summary_after_move(scene_name: str, probe_name: str, what: str, seconds: float) -> None:
    """The panel's one line (the bake's) with what the last move did after it, replacing an earlier move's."""
    probe = _probe_named(scene_name, probe_name)
    if probe is not None:
        s = probe.gs_ibl_probe
        s.last_summary = f"{s.last_summary.split(MOVED_SUMMARY)[0]}{MOVED_SUMMARY}{what} in {seconds:.1f} s"


def _moved_names(depsgraph) -> set[str]:
    return {u.id.original.name for u in depsgraph.updates
            if u.is_updated_transform and isinstance(u.id, bpy.types.Object)}


def _look(scene: bpy.types.Scene) -> None:
    """Remember every probe's state as it is now (seen_states): what its next update is compared with."""
    for obj in scene.objects:
        if is_probe(obj):
            splats = auto_splats(scene, obj)
            if splats is not None:
                seen_states[(scene.name, obj.name)] = bake_state(obj, splats, scene)


@persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """Notes auto-updating probes whose probe or splat object really moved and (re)starts one debounce timer: the
    re-bake runs once the objects have stayed still for the probe's Update Delay, so a drag bakes once.

    "Really moved": reported with a transform update and its bake state changed since the last update looked
    (seen_states). Blender reports a transform update for any edit of the probe's settings too (Strength, a
    checkbox), and a state that differed from the last bake for another reason (the splats edited, a file opened)
    then re-baked on a Strength change ("re-baking moved probes" though nothing moved)."""
    global _rebaseline_next, _adopt_saved_next
    clear_lost_splats(scene)
    refresh_notice(scene)  # the status bar says when a bake is out of date (stale.py)
    if _adopt_saved_next:
        _adopt_saved_next = False
        for sc in bpy.data.scenes:
            _adopt_saved(sc)
    if _rebaseline_next:
        _rebaseline_next = False
        _rebaseline()
        return
    moved = _moved_names(depsgraph)
    delay = None
    for obj in scene.objects:
        if not is_probe(obj):
            continue
        splats = auto_splats(scene, obj)
        if splats is None:
            continue
        key = (scene.name, obj.name)
        state = bake_state(obj, splats, scene)
        before = seen_states.get(key, baked_states.get(key, state))  # never looked at: nothing to compare with
        seen_states[key] = state
        if not moved or not obj.gs_ibl_probe.auto_update:
            continue
        meshes = _moved_lit_meshes(scene, obj, moved)
        if meshes:
            _pending_meshes.setdefault(key, set()).update(meshes)
        # a probe parented to a mesh ("follows" it) is reported moved with it
        lighting = {splats.name} | {name for name, _key in state[2]}  # every splat object that lights it
        really = (obj.name in moved or bool(lighting & moved)) and state != before
        if not really or state == baked_states.get(key):
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
    tag_redraw()


def _pending_job(keys: list[tuple[str, str]], relight: dict[tuple[str, str], set[str]]) -> Job:
    global last_auto_error, auto_bakes, auto_relights
    for i, (scene_name, probe_name) in enumerate(keys):
        part = (0.99 * i / len(keys), 0.99 * (i + 1) / len(keys))  # each probe's part of the job's progress
        scene = bpy.data.scenes.get(scene_name)
        probe = scene.objects.get(probe_name) if scene is not None else None
        if probe is None or not is_probe(probe):
            continue
        splats = auto_splats(scene, probe)
        if splats is None:
            continue
        if bake_state(probe, splats, scene) == baked_states.get((scene_name, probe_name)):
            meshes = [scene.objects[n] for n in sorted(relight.get((scene_name, probe_name), ()))
                      if n in scene.objects and probe.gs_ibl_probe.world is not None]
            volume = probe.gs_ibl_probe.lighting == "VOLUME"
            # noted again while an earlier relight or growth ran (a drag paused, then ended; the first update after
            # opening a file): those it lit where they stand now need nothing
            meshes = [m for m in meshes if _moved_lit_meshes(scene, probe, {m.name})]
            if meshes:  # only lit meshes moved: their light is chosen again (the volume grown), the World stays
                try:
                    auto_relights += 1
                    t0 = time.perf_counter()
                    steps = volume_light_steps(scene, probe, grow=True) if volume else relight_steps(scene, probe,
                                                                                                      meshes)
                    text, _choices = yield from within(steps, *part)
                    seconds = time.perf_counter() - t0
                    text += f" (after a move, {seconds:.1f} s)"
                    _summary_after_move(scene_name, probe_name, "light volume grown" if volume else
                                        f"{len(meshes)} mesh{'es' if len(meshes) != 1 else ''} relit", seconds)
                    print(f"GS-IBL (update when moved): {text}")
                    # Details says what lights the meshes now: the volume's line of the bake's report, or Auto's
                    # choice for the meshes that moved beside the bake's own line
                    if volume:
                        _replace_line(scene_name, probe_name, VOLUME_PREFIX, text)
                    else:
                        _replace_line(scene_name, probe_name, AUTO_MOVED, AUTO_MOVED + text.removeprefix(AUTO_PREFIX))
                except (ValueError, RuntimeError, OSError, MemoryError) as e:
                    last_auto_error = f"{probe_name}: {e}"
                    print(f"GS-IBL (update when moved): {last_auto_error}")
            continue  # the probe moved back to where it was baked, or only meshes moved
        try:
            auto_bakes += 1
            _, text, warning = yield from within(bake_job(scene, probe, splats), *part)
            last_auto_error = None
            print(f"GS-IBL (update when moved): {text}" + (f"; WARNING: {warning}" if warning else ""))
        except (ValueError, RuntimeError, OSError, MemoryError) as e:
            last_auto_error = f"{probe_name}: {e}"
            probe = _probe_named(scene_name, probe_name)
            if probe is not None and is_probe(probe):
                probe.gs_ibl_probe.last_report = f"{WARNING_PREFIX}automatic re-bake failed:\n{e}"
                probe.gs_ibl_probe.last_summary = "Automatic re-bake failed: the World keeps the last bake's light"
            print(f"GS-IBL (update when moved): {last_auto_error}")


@persistent
def on_load_pre(*_args) -> None:
    global _rebaseline_next, _adopt_saved_next
    cancel_all()  # their results would land in the file being closed
    _rebaseline_next = _adopt_saved_next = False
    _pending.clear()
    _pending_meshes.clear()
    lit_places.clear()
    forget_volumes()
    baked_states.clear()  # names of another file's probes
    seen_states.clear()


@persistent
def on_load_post(*_args) -> None:
    global _adopt_saved_next
    for scene in bpy.data.scenes:  # the opened file's places: its first move is compared with them
        _look(scene)
    _adopt_saved_next = True
    # a file saved with an out-of-date bake says so when opened, once the objects' matrices are evaluated: at
    # load_post they are not, and every saved bake read "the probe moved" until the next bake (the GUI evaluates
    # the file before a timer's first call; headless, no status bar shows it)
    if not bpy.app.timers.is_registered(notice_after_load):
        bpy.app.timers.register(notice_after_load, first_interval=0.0)


def notice_after_load() -> None:
    """Timer (one-shot): the status bar's line about the opened file's out-of-date bakes."""
    if bpy.context.scene is not None:
        bpy.context.evaluated_depsgraph_get()  # evaluated already in the GUI; in case it is not
        refresh_notice(bpy.context.scene)


_HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("load_pre", on_load_pre), ("load_post", on_load_post))


def register_handlers() -> None:
    handlers.add(_HANDLERS)


def unregister_handlers() -> None:
    handlers.remove(_HANDLERS)
    for timer in (run_pending, notice_after_load):
        if bpy.app.timers.is_registered(timer):
            bpy.app.timers.unregister(timer)
    on_load_pre()
