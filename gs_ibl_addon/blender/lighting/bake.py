"""Baking a probe into Blender: probe properties -> core.bake.bake_probe -> images, World, node group.

Used by the Bake operator, by headless scripts (``bpy.ops.gs_ibl.bake_probe()`` or ``bake_into_world``) and by
Update When Moved (auto_update.py), which reads what each bake depended on (``baked_states``, ``lit_places``).
"""
from __future__ import annotations

import time
from typing import Callable

import bpy
import numpy as np

from ...core.bake import ProbeSettings, bake_probe, check_fits_device
from ...core.tolerance import plan_text
from ...core.probe.highlights import highlight_text
from ...core.probe.holes import hole_fill_text, hole_warning
from ...core.probe.lights import lights_text
from ...core.probe.near import near_warning
from ...core.probe.latlong import cube_to_latlong
from ...core.settings import method_from_blender
from ..splats import cache as splat_cache
from .stamps import BAKE_KEY, stamp
from .stale import animated_text, record_bake, record_meshes, refresh_notice, while_baking
from .auto_light import AUTO_KEY, auto_light_steps, remove_auto_light
from .volume import volume_light_steps
from .object_probes import lit_meshes
from . import local_light as ll
from .sources import in_scene, lighting_set, require_splats, set_line
from . import world as gw
from .lights_from_probe import set_lights_strength, sync_lights
from ..common.datablocks import is_ours, is_probe
from ..common.jobs import Job, Step, Work, run_now, within
from ..splats.object import splat_count

HOLE_WARNING = 0.01  # warn when more of the sphere than this sees no splat
WARNING_PREFIX = "Warning: "  # a report line the panel shows with a warning icon


def probe_settings(props) -> ProbeSettings:
    """The core's settings from a probe's properties (Object.gs_ibl_probe)."""
    return ProbeSettings(method=method_from_blender(props.method), face_size=int(props.face_size),
                         irradiance_size=int(props.irradiance_size), tolerance=float(props.tolerance),
                         highlight_gain=float(props.highlight_gain), lights=int(props.lights))


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


def _background_world(scene: bpy.types.Scene) -> bpy.types.World | None:
    """The World whose backdrop Keep Background keeps: the one before we first took over the scene's World."""
    previous = scene.get(gw.PREVIOUS_WORLD)
    if not isinstance(previous, bpy.types.World):
        previous = scene.world if scene.world is not None and scene.world.get(gw.MARKER) != "world" else None
    return previous


def rebuild_world(scene: bpy.types.Scene, probe: bpy.types.Object) -> bpy.types.World | None:
    """The probe's World made again from the images its last bake wrote, with its settings as they are now (Keep
    Background takes effect at once, no re-bake); the scene keeps using it where it used the old one. None when
    the probe has no baked World yet."""
    s = probe.gs_ibl_probe
    old = s.world
    if s.radiance_image is None or not is_ours(old, "world"):
        return None
    bake_id = old.get(BAKE_KEY)
    used = scene.world == old
    s.world = gw.build_world(s.radiance_image, s.strength, s.keep_background, _background_world(scene),
                             replace=_own(probe, "world"))
    if bake_id is not None:
        s.world[BAKE_KEY] = bake_id  # the same bake's light (stamps.py)
    if used and scene.world != s.world:  # the old one is shared with a duplicated probe: not replaced
        scene.world = s.world
    return s.world


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
    s.world = gw.build_world(s.radiance_image, s.strength, s.keep_background, _background_world(scene),
                             replace=_own(probe, "world"))
    if s.assign_world:
        gw.use_world(scene, s.world)
        if s.mute_native_splats:
            gw.mute_native_splats(scene)
        else:
            gw.unmute_native_splats(scene)
    return s.world


def apply_strength(scene: bpy.types.Scene, probe: bpy.types.Object) -> None:
    """The probe's Strength on everything its last bake lit, without a re-bake: its World's strength node, its
    lights, and the local-light group of the meshes it lights (Lighting Auto's, and those the World it gave the
    scene lights). Other probes' Worlds (in this scene or others) keep theirs."""
    s = probe.gs_ibl_probe
    strength = float(s.strength)
    if is_ours(s.world, "world"):
        gw.set_world_strength(s.world, strength)
    set_lights_strength(probe, strength)
    scene_world = s.world is not None and scene.world == s.world
    for obj in scene.objects:
        if obj.type == "MESH" and (obj.get(AUTO_KEY) == probe.name or (scene_world and ll.has_local_light(obj))):
            ll.set_strength(obj, strength)


FILTER_STAGES = ("sh_project", "irradiance", "ggx")  # the filters a bake runs; their other keys are details


def filter_gpu_ms(timings: dict[str, float]) -> float:
    """The filters' GPU time of a bake: SH projection + irradiance (+ GGX when baked).

    Only these totals: ``<stage>_wall`` (the same work timed on the host), ``<stage>.<step>`` (the per-step split of
    the total) and ``upload`` would count time twice or time the host. Where a stage ran on the CPU its value is
    wall time (core/probe/filters.py).
    """
    return sum(timings.get(k, 0.0) for k in FILTER_STAGES)


def summary(result, seconds: float, stages: dict[str, float] | None = None,
            splats_name: str | None = None) -> tuple[list[str], str | None]:
    """(lines saying what the bake did and how long each part took, hole warning or None). ``stages``: wall
    seconds of the bake's parts, in order (reading, turning SH and upload when this bake made the splats' GPU copy;
    bake; writing; each mesh's light); with "other" (what they leave of ``seconds``) they add up to it.
    ``splats_name``: the splat object baked, named by the warning of a probe inside its splats."""
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
    near = near_warning(result.near_splats, splats_name)  # only where the bake had the splats on the host
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
    return while_baking(scene.name, probe.name, _bake_steps(scene.name, probe.name, splats, settings))


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
    """The worker's part of a bake: the core bake and its lat-long images. ``local``: per splat object that lights
    the probe (splats as read, matrix, object name), for a bake that uploads its own copy."""
    if local is not None:  # the gain goes on the splats (exact), so this bake uploads its own copy
        from ..splats.object import merged_world
        result = bake_probe(merged_world(local), where, settings, progress=progress)
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
    # The job's progress in parts that end where the next begins, so it says 100% only at its end: the upload (when
    # this bake makes it), the bake, writing, and Lighting Auto's probes for each mesh, which can take longer than
    # the bake (measured: 10 s after a 0.7 s bake for one mesh lit by a grid).
    scene, probe, splats = _named(scene_name, probe_name, splats_name)
    meshes = probe.gs_ibl_probe.lighting in ("AUTO", "VOLUME") and bool(lit_meshes(scene, probe))
    baked, written = ((0.05, 0.35), 0.4) if meshes else ((0.05, 0.95), 0.97)
    lighting = lighting_set(scene, splats)  # the probe's own splats and every other one in renders
    lighting_names = [o.name for o in lighting]  # (the objects may be deleted while a worker bakes)
    yield Step(f"reading {sum(splat_count(o) for o in lighting):,} splats", 0.0)
    uploads = splat_cache.uploads
    # read and uploaded once, shared with the overlay and re-bakes (a set of objects: one merged copy)
    cached = yield from within(splat_cache.set_steps(lighting), 0.0, baked[0])
    if splat_cache.uploads != uploads:  # this bake read them: reading, turning SH, upload (a wait is "other")
        stages.update(cached.timings)
    t = time.perf_counter()
    scene, probe, splats = _named(scene_name, probe_name, splats_name)
    check_fits_device(settings, cached.renderer.ctx, cached.renderer.scene_count)
    where = np.array(probe.matrix_world.translation, np.float64)
    local = None
    if settings.highlight_gain != 1:
        from ..splats.object import read_steps
        local = []
        for o in lighting_set(scene, splats):
            local.append((*(yield from read_steps(o)), o.name))
    result, radiance, irradiance = yield Work(_bake_and_resample, where, settings, cached, local, span=baked)
    t = lap("bake", t)  # renders, filters and the host work between them
    scene, probe, splats = _named(scene_name, probe_name, splats_name)
    yield Step("writing the light into Blender", baked[1])
    apply_probe_images(scene, probe, radiance, irradiance)
    sync_lights(scene, probe, result.lights, probe.gs_ibl_probe.strength)
    t = lap("writing", t)
    if probe.gs_ibl_probe.splats is None:
        probe.gs_ibl_probe.splats = splats  # the field says what was baked (and what Update When Moved follows)
    baked_states[(scene.name, probe.name)] = seen_states[(scene.name, probe.name)] = bake_state(probe, splats, scene)
    record_bake(probe, splats, lighting_set(scene, splats)[1:])
    auto, choices = None, None
    if probe.gs_ibl_probe.lighting == "AUTO":
        yield Step("choosing each mesh's light", written)
        auto, choices = yield from within(relight_steps(scene, probe), written, 0.99)
        scene, probe, splats = _named(scene_name, probe_name, splats_name)
        t = lap("each mesh's light", t)
    elif probe.gs_ibl_probe.lighting == "VOLUME":
        yield Step("baking the light volume", written)
        auto, lit = yield from within(volume_light_steps(scene, probe), written, 0.99)
        choices = f"Volume: {len(lit['lit'])} mesh{'es' if len(lit['lit']) != 1 else ''}" + (
            f", {len(lit['outside'])} outside (World)" if lit["outside"] else "")
        scene, probe, splats = _named(scene_name, probe_name, splats_name)
        t = lap("light volume", t)
    else:
        remove_auto_light(scene, probe)  # World Probe: the World alone, for meshes Auto lit before too
    seconds = time.perf_counter() - t0
    lines, warning = summary(result, seconds, stages, splats_name)
    line = set_line(lighting_names)
    if line:
        lines.insert(1, line)
    if auto:
        lines.append(auto)
    if animated_text(probe) is not None:  # the light is where the probe stands now, not along its path
        lines.append(animated_text(probe, scene.frame_current))
    probe.gs_ibl_probe.last_report = "\n".join(lines + ([WARNING_PREFIX + warning] if warning else []))
    probe.gs_ibl_probe.last_summary = summary_line(result, seconds, choices, len(lighting_names))
    stamp(probe)
    refresh_notice(scene)
    return result, ", ".join(lines), warning


def lighting_choice(choices) -> str:
    """How the bake lit meshes, in a few words: "World", Lighting Auto's choices ("Auto: 3 meshes (2 World,
    1 grid)") or Lighting Volume's (a line of its own, passed as text)."""
    if choices is None:
        return "lit by the World"
    if isinstance(choices, str):
        return choices
    if not choices:
        return "Auto: no mesh inside the splats"
    counts = {k: sum(c.kind == k for c in choices) for k in ("world", "probe", "grid")}
    words = {"world": "World", "probe": "own probe", "grid": "grid"}
    parts = ", ".join(f"{n} {words[k]}" for k, n in counts.items() if n)
    return f"Auto: {len(choices)} mesh{'es' if len(choices) != 1 else ''} ({parts})"


def summary_line(result, seconds: float, choices=None, splat_objects: int = 1) -> str:
    """The report in one line, what the panel shows with the rest one click away: time, the splat objects when
    several lit it, face size, the estimated error (with Face Size 0: the tolerance's estimate) and how meshes are
    lit."""
    st = result.settings
    face = st.get("face_size", np.asarray(result.radiance).shape[1])
    parts = [f"Baked in {seconds:.1f} s"] + ([f"{splat_objects} splat objects"] if splat_objects > 1 else []) + [
        f"{face}x{face} faces"]
    plan = st.get("tolerance_plan") or {}
    if "estimated_error" in plan:
        error = 100 * plan["estimated_error"]
        parts.append("error < 0.01%" if error < 0.01 else f"error ~{error:.2g}%")
    return ", ".join(parts + [lighting_choice(choices)])


# What each bake depended on, for Update When Moved (auto_update.py) and Lighting Auto's re-choices.
baked_states: dict[tuple[str, str], tuple] = {}  # (scene name, probe name) -> bake_state() of its last bake
seen_states: dict[tuple[str, str], tuple] = {}  # (scene, probe) -> its bake_state() when a depsgraph update (or
# its bake) last looked: a probe "moved" only where this changed (auto_update.py)
lit_places: dict[tuple[str, str], dict[str, bytes]] = {}  # (scene, probe) -> {mesh: its matrix when its light
# was chosen}


def bake_state(probe: bpy.types.Object, splats: bpy.types.Object | None,
               scene: bpy.types.Scene | None = None) -> tuple:
    """What a bake's light depends on that a move changes: the probe's position and the placement and data of the
    splats that light it (its own ``splats`` and, given the ``scene``, the others shown in renders: which they are
    and each one's data key).

    A re-bake is due only when this differs from the last bake's: depsgraph updates also report objects whose
    transform did not change (a bake writing the probe's own properties is one), which once made every bake
    schedule the next."""
    others = () if splats is None or scene is None else tuple(
        (o.name, splat_cache.data_key(o)) for o in lighting_set(scene, splats)[1:])
    return (tuple(round(float(c), 9) for c in probe.matrix_world.translation),
            splat_cache.data_key(splats) if splats is not None else None, others)


def place_key(obj: bpy.types.Object) -> bytes:
    return np.array(obj.matrix_world, np.float64).round(9).tobytes()


def relight_steps(scene: bpy.types.Scene, probe: bpy.types.Object, meshes: list | None = None) -> Job:
    """Lighting Auto as a job: choose the light of ``meshes`` (default: every lit mesh) and remember where they
    were. Its result: (the report line, the choices)."""
    scene_name, probe_name = scene.name, probe.name
    text, choices = yield from auto_light_steps(scene, probe, meshes)
    scene = bpy.data.scenes[scene_name]  # auto_light_steps found it after its workers
    places = lit_places.setdefault((scene_name, probe_name), {})
    for c in choices:
        obj = scene.objects.get(c.name)
        if obj is not None:
            places[c.name] = place_key(obj)
    probe = scene.objects.get(probe_name)
    if probe is not None:
        record_meshes(scene, probe, [c.name for c in choices])
    return text, choices
