"""Bake a light probe: splats -> radiance cubemap (GPU) -> irradiance (GPU filter) -> ProbeResult.

``auto`` models no more than the probe needs, measured on the probe itself: with face size 0 the cube is rendered
at 32^2 and 64^2, and the change between the two (core/tolerance.py) estimates the error (relative RMS
irradiance); where it is over the tolerance, the faces whose part of the change is largest are rendered finer,
until the estimate meets it. With irradiance size 0 the irradiance faces are chosen too, by the error of reading
between texels. The filter is the exact texel integral on
the GPU
(docs/accuracy.md: it costs about what SH projection costs and has neither SH's ringing nor the cosine
convolution's sampling noise); the 9 SH coefficients are still computed and stored in probe.json.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from typing import Callable

import numpy as np

from .probe import ProbeResult, filter_probe
from .probe.ggx import DEFAULT_ROUGHNESS as GLOSSY_ROUGHNESS
from .probe.gpu_filters import gpu_ggx_prefilter
from .probe.gpu_assemble import GpuFaces, HostFaces, KeptCube
from .probe.gpu_holes import GPU_FILLS, covered_means, fill_frame_holes
from .probe.highlights import gain_clipped_splats, recover_highlights
from .probe.holes import fill_holes
from .probe.lights import extract_lights
from .probe.near import near_splats
from .cubemap import FACE_NAMES
from .render.renderer import SplatRenderer
from .render.views import ViewBatch
from .scene import SplatScene
from .stage_times import StageTimes
from .vk import get_context
from .probe.reference import exact_irradiance_parts
from .tolerance import ErrorModel, check_tolerance, choose_irradiance_size, relative_rms, search_face
from .settings import (AUTO_FIRST_FACE, AUTO_MAX_FACE, DEFAULT_HOLE_FILL, DEFAULT_IRRADIANCE_SIZE, DEFAULT_LOD,
                       DEFAULT_LOD_K, DEFAULT_METHOD, DEFAULT_TOLERANCE, HOLE_FILLS, LOD_MODES, MAX_IRRADIANCE_SIZE,
                       IRRADIANCE_SIZES, METHOD_ALIASES, METHOD_NAMES)

# From this face size on the six faces are rendered one at a time, each reporting progress: at 1024^2 and above a
# face takes seconds to minutes on a CPU device, and six views in one batch would give no sign of life meanwhile.
FACE_BY_FACE_FROM = 1024
# Face size 0 sizes each face by itself from this size up (the search's second render), and writes a radiance cube
# of at most RADIANCE_OUT_MAX (finer faces box-filtered down, keeping their light; coarser ones interpolated up).
PER_FACE_BASE = 2 * AUTO_FIRST_FACE
RADIANCE_OUT_MAX = 128
PER_FACE_ROUNDS = 4  # plan, render, measure what the finer faces changed (one doubling each): at most this often
# Face size 0's per-face cube is put together on the GPU (probe/gpu_assemble.py GpuFaces); False: on the host from
# the faces read back, and filled and filtered from there (HostFaces, the reference; benchmarks' "before").
GPU_ASSEMBLE = True


class BadSetting(ValueError):
    """A bake setting out of range: ``option`` is its ProbeSettings name (the command line shows ``--face-size``)."""

    def __init__(self, option: str, value, message: str) -> None:
        self.option, self.value = option, value
        super().__init__(message)


@dataclass
class ProbeSettings:
    method: str = DEFAULT_METHOD  # one of settings.METHOD_NAMES
    face_size: int = 0  # radiance face size; 0 = the smallest estimated to meet the tolerance (core/tolerance.py)
    irradiance_size: int = DEFAULT_IRRADIANCE_SIZE  # irradiance cube face (lat-long 4x as wide); 0 = from tolerance
    tolerance: float = DEFAULT_TOLERANCE  # relative RMS irradiance error the face size (and size 0s) are chosen for
    sh_order: int = 2
    glossy: bool = False  # also GGX prefiltered radiance for glossy surfaces (slower)
    max_face_size: int = AUTO_MAX_FACE
    lod: str = DEFAULT_LOD  # one of settings.LOD_MODES: "auto" renders merged splats where the probe allows
    lod_k: float = DEFAULT_LOD_K  # with lod "auto": a merged node is drawn once its cell spans <= lod_k pixels
    hole_fill: str = DEFAULT_HOLE_FILL  # one of settings.HOLE_FILLS: the light of directions with no splat
    hole_colour: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the fill's radiance with hole_fill "constant"
    highlight_gain: float | str = 1.0  # clipped splats' light times this, or "auto" (core/probe/highlights.py)
    lights: int = 0  # split up to this many bright compact regions off as lights (core/probe/lights.py)
    extra: dict = field(default_factory=dict)  # passed through to filter_probe (sample counts, windows...)


def check_settings(s: ProbeSettings) -> str:
    """The internal method name for valid settings; a BadSetting naming the first bad one otherwise. No device,
    no file: callers run it before reading anything."""
    method = METHOD_ALIASES.get(str(s.method).lower())
    if method is None:
        raise BadSetting("method", s.method, f"unknown irradiance method {s.method!r}: use one of "
                                             f"{', '.join(METHOD_NAMES)}")
    for name, value, low in (("face_size", s.face_size, 0), ("irradiance_size", s.irradiance_size, 0),
                             ("max_face_size", s.max_face_size, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise BadSetting(name, value, f"{name.replace('_', ' ')} {value!r} must be a whole number, "
                                          f"{low} or more" + (" (0: from the tolerance)" if low == 0 else ""))
    if s.irradiance_size > MAX_IRRADIANCE_SIZE:
        raise BadSetting("irradiance_size", s.irradiance_size,
                         f"irradiance size {s.irradiance_size} is more than {MAX_IRRADIANCE_SIZE}; irradiance is "
                         "smooth and 16-64 is plenty: use 64 or less")
    if s.lod not in LOD_MODES:
        raise BadSetting("lod", s.lod, f"unknown level of detail {s.lod!r}: use one of {', '.join(LOD_MODES)}")
    if isinstance(s.lod_k, bool) or not (isinstance(s.lod_k, (int, float)) and 0 < s.lod_k <= 64):
        raise BadSetting("lod_k", s.lod_k, f"lod k {s.lod_k!r} must be a number of pixels above 0 and at most 64")
    if s.hole_fill not in HOLE_FILLS:
        raise BadSetting("hole_fill", s.hole_fill, f"unknown hole fill {s.hole_fill!r}: use one of "
                                                   f"{', '.join(HOLE_FILLS)}")
    try:
        colour = np.asarray(s.hole_colour, np.float64).reshape(3)
    except (TypeError, ValueError):
        colour = None
    if colour is None or not np.all(np.isfinite(colour)) or np.any(colour < 0):
        raise BadSetting("hole_colour", s.hole_colour, f"hole colour {s.hole_colour!r} must be three numbers "
                                                       "R G B, 0 or more (linear radiance)")
    if s.highlight_gain != "auto" and (isinstance(s.highlight_gain, bool) or not isinstance(
            s.highlight_gain, (int, float)) or not 1 <= s.highlight_gain <= 1e6):
        raise BadSetting("highlight_gain", s.highlight_gain, f"highlight gain {s.highlight_gain!r} must be a number "
                                                             "from 1 (off) up, or auto")
    if isinstance(s.lights, bool) or not isinstance(s.lights, (int, np.integer)) or not 0 <= s.lights <= 8:
        raise BadSetting("lights", s.lights, f"lights {s.lights!r} must be a whole number from 0 (none) to 8")
    try:
        check_tolerance(s.tolerance)
    except ValueError as e:
        raise BadSetting("tolerance", s.tolerance, str(e)) from None
    return method


def check_probe_position(position) -> np.ndarray:
    """Three finite numbers as float64, or a BadSetting saying what is wrong."""
    try:
        pos = np.asarray(position, np.float64).reshape(3)
    except (TypeError, ValueError):
        raise BadSetting("probe", position, f"probe position {position!r} must be three numbers X Y Z") from None
    if not np.all(np.isfinite(pos)):
        raise BadSetting("probe", position, f"probe position {pos.tolist()} is not finite (NaN or infinity): "
                                            "give three ordinary numbers")
    return pos


def largest_face(s: ProbeSettings) -> int:
    """The largest radiance face the bake can render: the fixed size, or the search's limit."""
    return int(s.face_size) or int(s.max_face_size)


def largest_irradiance(s: ProbeSettings) -> int:
    """The largest irradiance face the bake can make: the fixed size, or the largest size 0 may choose."""
    return int(s.irradiance_size) or IRRADIANCE_SIZES[-1]


def check_fits_device(s: ProbeSettings, ctx=None, splats: int = 0, sh_coeffs: int = 16) -> None:
    """Refuse face or irradiance sizes the device or host memory cannot hold (limits.TooBig names the option)."""
    from .limits import check_fits, cube_bytes
    face = largest_face(s)
    s = replace(s, irradiance_size=largest_irradiance(s))
    check_fits("face_size" if s.face_size else "max_face_size", face,
               cube_bytes(face, s.irradiance_size, splats, sh_coeffs, s.glossy),
               lambda v: cube_bytes(v, s.irradiance_size, splats, sh_coeffs, s.glossy), ctx,
               "^2 faces" + (f" with {splats:,} splats" if splats else ""))
    check_fits("irradiance_size", s.irradiance_size, cube_bytes(face, s.irradiance_size, splats, sh_coeffs, s.glossy),
               lambda v: cube_bytes(face, v, splats, sh_coeffs, s.glossy), ctx, "^2 irradiance faces")


def estimate_output_bytes(s: ProbeSettings, half: bool = False, cube_faces: bool = False) -> int:
    """Upper bound of the bytes write_probe (plus a preview PNG) writes for these settings."""
    from .limits import exr_bytes
    face = largest_face(s)
    s = replace(s, irradiance_size=largest_irradiance(s))
    total = exr_bytes(4 * face, 2 * face, 3, half) + exr_bytes(max(64, 4 * s.irradiance_size),
                                                                 max(32, 2 * s.irradiance_size), 3, half)
    levels = [max(4, face >> k) for k in range(5)] if s.glossy else []
    total += sum(exr_bytes(max(64, 4 * m), max(32, 2 * m), 3, half) for m in levels)
    if cube_faces:
        total += 6 * (exr_bytes(face, face, 4, half) + exr_bytes(s.irradiance_size, s.irradiance_size, 3, half)
                      + sum(exr_bytes(m, m, 3, half) for m in levels))
    return total + (4 << 20) + (1 << 20)  # preview PNG and probe.json


def default_probe_position(scene: SplatScene) -> np.ndarray:
    """Opacity-weighted centre of mass of the splats (inside any enclosing capture such as a room)."""
    if scene.count == 0:
        return np.zeros(3)
    w = scene.opacities.astype(np.float64)
    return (scene.positions.astype(np.float64) * w[:, None]).sum(0) / max(w.sum(), 1e-12)


def choose_face(probe_at: Callable[[int, float], object], model, s: ProbeSettings, lod_k: float,
                say: Callable[[str, float], None], largest: int | None = None) -> tuple[object, int, list, dict, float]:
    """Face size 0: the face (and whether to keep the level of detail) from the tolerance's error model, for one
    probe (bake_probe) or a batch (bake_batch, a model per probe, the worst deciding). ``probe_at(face, lod_k)``
    renders and filters. Returns (the kept render, its face, the trials, the tolerance plan, the lod_k kept)."""
    plan: dict = {}
    if lod_k > 0:  # the level of detail is kept only where its own error is within half the tolerance
        merged = probe_at(AUTO_FIRST_FACE, lod_k).irradiance
        plan["lod_error"] = float(np.max(model.change(merged, probe_at(AUTO_FIRST_FACE, 0.0).irradiance)))
        lod_k = lod_k if plan["lod_error"] <= s.tolerance / 2 else 0.0
    limit = int(s.max_face_size) if largest is None else min(int(s.max_face_size), largest)
    result, face, trials, est = search_face(lambda f: probe_at(f, lod_k), model, s.tolerance, AUTO_FIRST_FACE,
                                            limit, say)
    plan.update(model=model.kind, estimated_error=est, met=est <= s.tolerance)
    return result, face, trials, plan, lod_k


def parts_on_gpu(ctx) -> bool:
    """Whether irradiance_parts (and the per-face search's GpuFaces) split a change on the device: a GPU, not a CPU
    device (lavapipe), where numpy's integral is the faster. Benchmarks set it to time a GPU's host work on lavapipe
    (auto_bake_core.py --gpu-paths)."""
    return ctx is not None and not ctx.is_cpu


def irradiance_parts(change: np.ndarray, size: int, ctx=None) -> np.ndarray:
    """probe/reference.py exact_irradiance_parts of a (6, n, n, 3) cube change: on a GPU the exact filter of six
    cubes, each holding one face of the change (one submission; equal to the reference within float32 rounding,
    1e-9 of a 3e-3 part), where numpy's (normals x texels) cosine blocks took 25-80 ms of the host per call (32^2
    faces into 8^2-16^2); on a CPU device (ctx None or lavapipe) the reference itself, which runs there 3x faster
    than the same integral as a filter."""
    if not parts_on_gpu(ctx):
        return exact_irradiance_parts(change, size)
    from .probe.gpu_filters import filter_probes
    n = change.shape[1]
    one_face = np.zeros((6, 6, n, n, 3), np.float32)
    for f in range(6):
        one_face[f, f] = change[f, ..., :3]
    return filter_probes(one_face, size, "exact", n, ctx=ctx).irradiance.astype(np.float64)


def choose_face_sizes(probe_at: Callable[[int], ProbeResult], render_faces: Callable[[dict], object],
                      filter_cube: Callable[[object], ProbeResult], model: ErrorModel, s: ProbeSettings,
                      say: Callable[[str, float], None], keep: Callable[[], object],
                      faces_from: Callable[[object, object, int, int], object]
                      ) -> tuple[ProbeResult, list[int], list, dict]:
    """Face size 0: "model no more than the probe needs", per cube face.

    The probe is rendered at 32^2 and 64^2 and the change between them gives the error (tolerance.ErrorModel).
    Where that does not meet the tolerance the change is split into each face's part of it, each face gets the
    size its part predicts it needs (a lamp's face finer, a dim wall's kept at 64^2: ErrorModel.plan_faces), those
    faces are rendered again one doubling finer, and their parts, and from the second on their fall per doubling,
    are measured again from what they changed.
    ``render_faces({face: size})`` renders those faces' views, in face order (a RenderResult); ``keep()`` keeps
    the cube just rendered (read back; or on the GPU: probe/gpu_assemble.py KeptCube); ``faces_from(first, last,
    level, size)`` takes the search's two kept cubes (HostFaces; GpuFaces), puts together each round's cube at one
    size for ``filter_cube`` and splits what the faces changed into their parts of the irradiance (size^2, the
    change taken at level^2: irradiance_parts). Returns (the probe, per-face sizes, trials, the tolerance plan)."""
    limit = int(s.max_face_size)
    cubes: dict[int, object] = {}

    def kept(face: int) -> ProbeResult:  # the search's two cubes are small: kept for the per-face parts
        probe = probe_at(face)
        cubes[face] = keep()
        return probe

    result, face, trials, est = search_face(kept, model, s.tolerance, AUTO_FIRST_FACE, min(PER_FACE_BASE, limit),
                                            say)
    sizes = [face] * 6
    if est > s.tolerance and face < limit and len(cubes) == 2:
        first, m = min(cubes), int(result.irradiance.shape[1])
        faces = faces_from(cubes[first], cubes[face], first, m)  # level first: where the exact filter integrates
        model.take_parts(faces.parts(), [first] * 6, sizes, result.irradiance)
        for _ in range(PER_FACE_ROUNDS):
            plan = model.next_sizes(s.tolerance, limit)
            todo = {f: plan[f] for f in range(6) if plan[f] > sizes[f]}
            if not todo:
                break
            names = ", ".join(f"{FACE_NAMES[f]} {n}^2" for f, n in todo.items())
            say(f"rendering faces {names}", min(0.8, 0.1 + 0.15 * len(trials)))
            before = list(sizes)
            for f in todo:
                sizes[f] = todo[f]
            faces.put(render_faces(todo), todo, min(max(sizes), RADIANCE_OUT_MAX))
            finer = filter_cube(faces.cube)
            change = float(np.max(model.change(result.irradiance, finer.irradiance)))
            model.take_parts(faces.parts(), before, sizes, finer.irradiance)
            est = model.estimate_faces(sizes)
            trials.append({"face_size": max(sizes), "face_sizes": list(sizes), "change": change, "estimate": est})
            say(f"faces {'/'.join(map(str, sizes))}: irradiance moved {100 * change:.2f}%; estimated error "
                f"{100 * est:.2f}% ({model.kind} model, per face)", min(0.8, 0.1 + 0.15 * len(trials)))
            result = finer
            if est <= s.tolerance:
                break
    plan = {"model": model.kind, "estimated_error": est, "met": est <= s.tolerance, "face_sizes": list(sizes)}
    return result, sizes, trials, plan


def light_from_radiance(result: ProbeResult, s: ProbeSettings, colour_space: str,
                        hole_radiance: Callable[[np.ndarray], np.ndarray] | None = None,
                        highlights_done: bool = False) -> bool:
    """Fill the holes of ``result.radiance``, gain its clipped texels (unless the splats were gained) and split its
    lights off, in place; True when the radiance changed so its irradiance must be filtered again."""
    result.radiance, result.hole_fill = fill_holes(result.radiance, s.hole_fill, s.hole_colour, hole_radiance)
    if s.highlight_gain != 1 and not highlights_done:  # no scene to gain the splats of: the cube's clipped texels
        result.radiance, result.highlights = recover_highlights(result.radiance, s.highlight_gain, colour_space)
    result.radiance, result.lights = extract_lights(result.radiance, s.lights)
    return bool((result.hole_fill["fraction"] > 0 and s.hole_fill != "black") or result.highlights or result.lights)


def _search_and_filter(r: SplatRenderer, splat_count: int, pos: np.ndarray, s: ProbeSettings, method: str,
                       say: Callable[[str, float], None],
                       hole_radiance: Callable[[np.ndarray], np.ndarray] | None = None,
                       highlights_done: bool = False, times: StageTimes | None = None) -> ProbeResult:
    """Render (and, with face size 0, choose the face size), fill the holes, filter, and add the glossy maps when
    asked. ``times``: where each stage's wall and GPU time goes (core/stage_times.py)."""
    times = times or StageTimes(r.ctx)
    # a renderer holding a level of detail draws from it when asked (one built without renders every splat)
    lod_k = float(s.lod_k) if s.lod == "auto" and r.lod is not None else 0.0
    m_search = int(s.irradiance_size) or DEFAULT_IRRADIANCE_SIZE  # the size 0 chooses from is picked at the end

    def probe_at(face: int, lod: float = lod_k, keep: bool = False) -> ProbeResult:
        cube = ViewBatch.cubemap(pos, face)
        if face < FACE_BY_FACE_FROM:
            # The frame stays on the GPU: the filter reads back the irradiance only, the radiance is read once,
            # for the face size kept (below).
            # wait=False: the filter is queued behind the render and the host waits once for both.
            res = r.render(cube, timestamps=True, wait=False, lod_k=lod)
            source = res.frame
            if keep and GPU_ASSEMBLE:  # copied on the GPU for the per-face search, in the filter's submission
                source = KeptCube(res.frame, sum(isinstance(held, KeptCube) for held in faces))
                faces.append(source)
            probe = filter_probe(source, irradiance_size=m_search, method=method, sh_order=s.sh_order,
                                 roughness=None, read_radiance=False, splat_count=splat_count,
                                 device=r.ctx.device_name, **s.extra)
            probe.timings_ms.update({f"render_{k}": v for k, v in res.timings_ms.items()})
            return probe
        else:
            images, timings = [], {}
            for f, view in enumerate(cube.views):
                say(f"rendering face {f + 1} of 6 ({face}x{face})", 0.2 + 0.6 * f / 6)
                res = r.render(replace(cube, views=(view,)), timestamps=True, lod_k=lod)
                images += res.images
                for k, v in res.timings_ms.items():
                    timings[f"render_{k}"] = timings.get(f"render_{k}", 0.0) + v
        return filter_probe(np.stack(images), irradiance_size=m_search, method=method,
                            sh_order=s.sh_order, roughness=None, timings_ms=timings, use_gpu=True, vk_context=r.ctx,
                            splat_count=splat_count, device=r.ctx.device_name, **s.extra)

    def render_faces(todo: dict[int, int]):
        # one submission for every size: the probe's dilation is one size whatever the face (render/splat_math.py)
        chosen = sorted(todo)
        cube = ViewBatch.cubemap(pos, max(todo.values()))
        views = tuple(ViewBatch.cubemap(pos, todo[f]).views[f] for f in chosen)
        res = r.render(replace(cube, views=views), timestamps=True, wait=False)  # the faces' assembly queued behind
        rendered.append(res)
        return res

    def filter_cube(cube) -> ProbeResult:  # a host cube, or GpuFaces' (its radiance stays on the GPU)
        return filter_probe(cube, irradiance_size=m_search, method=method, sh_order=s.sh_order, roughness=None,
                            use_gpu=True, vk_context=r.ctx, read_radiance=False, splat_count=splat_count,
                            device=r.ctx.device_name, **s.extra)

    def keep():  # the cube probe_at(..., keep=True) just rendered
        return faces[-1] if GPU_ASSEMBLE else r.last_frame.read_cube()

    def faces_from(first, last, level: int, size: int):
        def on_host(change, size):
            return irradiance_parts(change, size, r.ctx)
        if not GPU_ASSEMBLE:
            faces.append(HostFaces(first, last, level, size, on_host))
        else:  # the parts where irradiance_parts takes them: the same filter on a GPU, else numpy
            faces.append(GpuFaces(first, last, level, size, None if parts_on_gpu(r.ctx) else on_host))
        return faces[-1]

    rendered: list = []  # renders of single faces (per-face sizes): their GPU times go to the kept probe's
    faces: list = []  # the search's kept cubes and faces (on the GPU: closed when the bake is done with them)
    try:
        trials: list[dict] = []
        plan: dict = {}
        face_sizes = None
        with times.stage("search" if not s.face_size else "render"):
            if s.face_size:
                face = int(s.face_size)
                say(f"rendering a {face}x{face} cubemap", 0.2)
                result = probe_at(face)
            elif lod_k == 0:
                result, face_sizes, trials, plan = choose_face_sizes(
                    lambda f: probe_at(f, keep=True), render_faces, filter_cube, ErrorModel(), s, say, keep,
                    faces_from)
                for res in rendered:
                    for k, v in res.timings_ms.items():
                        result.timings_ms[f"render_{k}"] = result.timings_ms.get(f"render_{k}", 0.0) + v
            else:
                result, face, trials, plan, lod_k = choose_face(probe_at, ErrorModel(), s, lod_k, say)
        # the kept probe's radiance: on the host (per-face cube put together there), else on the GPU in the last
        # frame rendered or the per-face cube put together there
        assembled = [held.cube for held in faces if isinstance(held, GpuFaces) and held.cube is not None]
        kept = assembled[-1] if assembled else r.last_frame
        if face_sizes is not None:
            face = int(np.shape(result.radiance)[1]) if result.radiance is not None else kept.face_size
        frame = filled_cube = None
        # Holes are filled on the kept probe (the search above compared the unfilled probes: a fill moves every
        # size alike) and it is filtered again; a probe without holes pays nothing. A one-colour fill of a probe
        # whose frame is still on the GPU, with nothing else to change on its cube, is filled there
        # (probe/gpu_holes.py) and its recorded filter runs again: no cube filled in numpy and uploaded again.
        if (result.radiance is None and s.hole_fill in GPU_FILLS and result.hole_fraction > 0 and s.lights == 0
                and (s.highlight_gain == 1 or highlights_done) and s.sh_order == 2):
            with times.stage("holes and lights"):
                t0 = time.perf_counter()
                frame = kept
                value = (covered_means(np.asarray(result.sh_coefficients)[None], [result.hole_fraction])[0]
                         if s.hole_fill == "mean" else np.asarray(s.hole_colour, np.float64))
                # one submission with the filter, the filled radiance's readback in it
                with fill_frame_holes(frame, value[None], read=True) as filled_cube:
                    filled = filter_probe(frame, irradiance_size=m_search, method=method, sh_order=s.sh_order,
                                          roughness=None, read_radiance=False, **s.extra)
                result.irradiance, result.sh_coefficients = filled.irradiance, filled.sh_coefficients
                result.hole_fill = {"method": s.hole_fill, "value": [float(v) for v in value],
                                    "fraction": float(result.hole_fraction)}
                result.timings_ms["hole_fill"] = (time.perf_counter() - t0) * 1e3
        with times.stage("radiance readback"):
            if result.radiance is None:  # the kept probe's frame (or per-face cube) is still on the GPU
                frame = kept
                result.radiance = filled_cube.read()[0] if filled_cube is not None else frame.read_cube()
        with times.stage("holes and lights"):
            if result.hole_fill is None and light_from_radiance(result, s, r.colour_space, hole_radiance,
                                                                highlights_done):
                t0 = time.perf_counter()
                filled = filter_probe(result.radiance[..., :3], irradiance_size=m_search, method=method,
                                      sh_order=s.sh_order, roughness=None, use_gpu=True, vk_context=r.ctx,
                                      **s.extra)
                result.irradiance, result.sh_coefficients = filled.irradiance, filled.sh_coefficients
                result.timings_ms["hole_fill"] = (time.perf_counter() - t0) * 1e3
                frame = None  # the glossy maps take the filled radiance
        m = m_search
        if not s.irradiance_size:
            with times.stage("irradiance size"):
                m, result.irradiance, between = choose_irradiance_size(
                    lambda size: filter_probe(result.radiance[..., :3], irradiance_size=size, method=method,
                                              sh_order=2, roughness=None, use_gpu=True, vk_context=r.ctx,
                                              **s.extra).irradiance,
                    s.tolerance)
            plan["irradiance_between_texels"] = {str(k): v for k, v in between.items()}
        if trials and result.sh_coefficients is not None:  # what 9 SH coefficients alone give (probe.json has them)
            from .probe.sh_project import sh_irradiance_faces
            plan["sh_error"] = relative_rms(sh_irradiance_faces(np.asarray(result.sh_coefficients, np.float64), m),
                                            result.irradiance)
        if s.glossy:
            say("prefiltering glossy maps", 0.85)
            with times.stage("glossy"):
                result.prefiltered, ggx_ms = gpu_ggx_prefilter(
                    frame if frame is not None else np.asarray(result.radiance), GLOSSY_ROUGHNESS, ctx=r.ctx)
            result.roughness = list(GLOSSY_ROUGHNESS)
            result.timings_ms["ggx"] = ggx_ms.get("total", 0.0)
        if trials:
            plan.update(face_size=face, irradiance_size=m, method=method, sh_order=s.sh_order,
                        lod="auto" if lod_k > 0 else "off")
        if face_sizes is not None:
            result.settings["face_sizes"] = list(face_sizes)  # rendered per face; "face_size" is the cube written
        result.settings.update({**asdict(s), "method_requested": s.method, "method": method, "face_size": face,
                                "irradiance_size": m, "face_size_trials": trials,
                                "converged": (not trials) or bool(plan.get("met")), "tolerance_plan": plan,
                                "probe_position": [float(x) for x in pos]})
        return result
    finally:
        for held in faces:  # the per-face cube is read: its buffers go back to the pool
            held.close()


def bake_probe(scene: SplatScene | None, probe_position=None, settings: ProbeSettings | dict | None = None,
               renderer: SplatRenderer | None = None,
               progress: Callable[[str, float], None] | None = None,
               hole_radiance: Callable[[np.ndarray], np.ndarray] | None = None,
               host_splats: SplatScene | None = None) -> ProbeResult:
    """Render the probe's radiance cubemap from the splats and filter it into irradiance (and optionally GGX).

    ``host_splats``: the splats on the host for the near-splat check when ``scene`` is None (without them the
    check is left out).

    Directions that meet no splat are filled by ``settings.hole_fill`` (core/probe/holes.py); ``hole_radiance``,
    a function of (M, 3) unit directions returning (M, 3) linear RGB, is the light of hole fill "environment"
    (Blender passes its World).

    ``scene`` may be None when ``renderer`` already holds the splats and ``probe_position`` is given: a caller that
    keeps splats on the GPU (Blender's splat_cache) then needs no CPU copy of them.
    """
    s = settings if isinstance(settings, ProbeSettings) else ProbeSettings(**(settings or {}))
    method = check_settings(s)
    if s.hole_fill == "environment" and hole_radiance is None:
        raise BadSetting("hole_fill", s.hole_fill, "hole fill 'environment' needs the environment's radiance "
                                                   "(bake_probe's hole_radiance); use mean, constant or black")
    if scene is None and (renderer is None or probe_position is None):
        raise ValueError("bake_probe without a scene needs both a renderer holding the splats and a probe position")
    pos = check_probe_position(default_probe_position(scene) if probe_position is None else probe_position)
    say = progress or (lambda _msg, _frac: None)
    t0 = time.perf_counter()
    r = renderer
    highlights = None
    stage_ms: dict[str, float] = {}  # each stage's wall and GPU time (core/stage_times.py), into the result's timings
    times = StageTimes(renderer.ctx if renderer is not None else get_context(), stage_ms)  # the upload's context
    if scene is not None and renderer is None:  # clipped splats gained before upload (core/probe/highlights.py)
        scene, highlights = gain_clipped_splats(scene, s.highlight_gain)
    try:
        if r is None:
            say(f"uploading {scene.count:,} splats", 0.0)
            with times.stage("upload"):
                r = SplatRenderer(scene, times.ctx, lod=s.lod == "auto")
        host = scene if scene is not None else host_splats
        result = _search_and_filter(r, r.scene_count, pos, s, method, say, hole_radiance, highlights is not None,
                                    times)
        result.highlights = highlights or result.highlights
        result.settings["colour_space"] = r.colour_space  # the colour rule the light was made with (probe.json)
        if host is not None:
            with times.stage("near splats"):
                result.near_splats = near_splats(host, pos)
    except Exception as e:
        from .limits import out_of_memory_advice
        n = scene.count if scene is not None else r.scene_count
        advice = out_of_memory_advice(e, f"baking {largest_face(s)}^2 faces of {n:,} splats",
                                      "use a smaller face size (or max face size) and irradiance size, "
                                      "or bake from fewer splats")
        if advice is None:
            raise
        raise advice from None
    finally:
        if renderer is None and r is not None:  # ours: give its GPU buffers back now, not whenever Python collects it
            r.close()
    result.timings_ms.update(stage_ms)
    result.timings_ms["bake_wall"] = (time.perf_counter() - t0) * 1e3
    say("done", 1.0)
    return result
