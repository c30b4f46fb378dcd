"""Bake many probes of one scene at once: N positions -> N ProbeResults from one render and one filter submission.

The splats are uploaded once and every probe is rendered in the same submission (SplatRenderer.render_probes); the
exact irradiance (or the order-2 SH) of all of them is one more submission over the whole frame
(gpu_filters.filter_probes); only the SH, the irradiance and the hole fractions are read back, and the radiance
only when it is kept, has holes to fill, or feeds the glossy maps. Each probe's result is what bake_probe gives at
its position with the same face size (tests/test_multi_probe.py).

Face size 0 follows bake_probe's rule (bake.choose_face: the tolerance's error model, core/tolerance.py) with one
model per probe, and all probes share the face the worst of them needs (a grid or per-object probes are compared
with each other: one resolution is what they should have anyway); each ProbeResult records the batch's
tolerance_plan with its own estimated error. Highlight gain and lights are bake_probe's too: the gain on the splats
when the batch uploads them, else on each cube's clipped texels (bake.light_from_radiance). Methods "convolve" and
"box" render in one batch and filter probe by probe.
"""
from __future__ import annotations

import copy
import time
from dataclasses import asdict
from typing import Callable

import numpy as np

from .bake import BadSetting, ProbeSettings, check_settings, choose_face, light_from_radiance
from .probe import ProbeResult, filter_probe
from .probe.highlights import gain_clipped_splats
from .probe.ggx import DEFAULT_ROUGHNESS as GLOSSY_ROUGHNESS
from .probe.gpu_filters import BATCH_METHODS, filter_probes, gpu_ggx_prefilter
from .probe.gpu_holes import GPU_FILLS, covered_means, fill_frame_holes
from .render.renderer import SplatRenderer, largest_probe_face
from .scene import SplatScene
from .settings import AUTO_FIRST_FACE
from .stage_times import StageTimes
from .tolerance import ErrorModel, relative_rms
from .vk import get_context


class ProbeModels:
    """One tolerance.ErrorModel per probe of a batch, read as one: the face is the largest any probe needs and the
    estimate the worst (search_face and choose_face take it in place of an ErrorModel)."""

    def __init__(self, probes: int) -> None:
        self.models = [ErrorModel() for _ in range(probes)]

    @property
    def kind(self) -> str:
        kinds = {m.kind for m in self.models}
        return kinds.pop() if len(kinds) == 1 else "mixed"

    def change(self, coarse: np.ndarray, fine: np.ndarray) -> np.ndarray:
        return np.array([relative_rms(a, b) for a, b in zip(coarse, fine)])

    def calibrate(self, coarse: int, fine: int, changes) -> float:
        return max(m.calibrate(coarse, fine, float(c)) for m, c in zip(self.models, changes))

    def estimate(self, face: int) -> float:
        return max(m.estimate(face) for m in self.models)

    def next_face(self, tolerance: float, current: int, largest: int) -> int:
        return max(m.next_face(tolerance, current, largest) for m in self.models)


class _Batch:
    """One render of the batch at one face size, filtered: what choose_face keeps or compares (``irradiance``)."""

    def __init__(self, frame, sh: np.ndarray, irradiance: np.ndarray, holes: np.ndarray, timings: dict) -> None:
        self.frame, self.sh, self.irradiance, self.holes, self.timings = frame, sh, irradiance, holes, timings


def check_probe_positions(positions) -> np.ndarray:
    """(N, 3) float64 finite positions, N >= 1, or a BadSetting naming the first bad one."""
    try:
        pos = np.asarray(positions, np.float64)
    except (TypeError, ValueError):
        raise BadSetting("probes", positions, f"probe positions {positions!r:.80} must be rows of three numbers "
                                              "X Y Z") from None
    if pos.ndim == 1 and pos.shape == (3,):
        pos = pos[None]
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise BadSetting("probes", positions, f"probe positions must be an (N, 3) array, got shape {pos.shape}")
    if len(pos) == 0:
        raise BadSetting("probes", positions, "no probe positions given: give at least one X Y Z")
    bad = np.flatnonzero(~np.all(np.isfinite(pos), 1))
    if len(bad):
        raise BadSetting("probes", positions, f"probe {int(bad[0])} at {pos[bad[0]].tolist()} is not finite (NaN or "
                                              f"infinity; {len(bad)} of {len(pos)} are): give ordinary numbers")
    return pos


def _filter_batch(frame, s: ProbeSettings, method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """(SH (N, 9, 3), irradiance (N, 6, m, m, 3), holes (N,), GPU timings) of every probe of the frame."""
    if method in BATCH_METHODS:
        f = filter_probes(frame, s.irradiance_size, method, s.extra.get("downsample_to", 32),
                          s.extra.get("sh_window", "none"))
        return f.sh_coefficients, f.irradiance, f.hole_fraction, f.timings_ms
    return _filter_cubes(frame.read_probes(), s, method, frame.ctx)


def _filter_cubes(cubes: np.ndarray, s: ProbeSettings, method: str, ctx
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """As _filter_batch, of cubes (N, 6, n, n, 3|4) on the host: one upload and submission for the batched
    methods, one filter per probe for convolve and box."""
    if method in BATCH_METHODS:
        f = filter_probes(cubes, s.irradiance_size, method, s.extra.get("downsample_to", 32),
                          s.extra.get("sh_window", "none"), ctx=ctx)
        return f.sh_coefficients, f.irradiance, f.hole_fraction, f.timings_ms
    out = [filter_probe(c, irradiance_size=s.irradiance_size, method=method, sh_order=2, roughness=None,
                        use_gpu=True, vk_context=ctx, **s.extra) for c in cubes]
    return (np.stack([p.sh_coefficients for p in out]), np.stack([p.irradiance for p in out]),
            np.array([p.hole_fraction for p in out]), {"filter_per_probe": sum(p.timings_ms.get("irradiance", 0.0)
                                                                                for p in out)})


def bake_probes(scene: SplatScene | None, positions, settings: ProbeSettings | dict | None = None,
                renderer: SplatRenderer | None = None, progress: Callable[[str, float], None] | None = None,
                hole_radiance: Callable[[np.ndarray], np.ndarray] | None = None,
                keep_radiance: bool = True) -> list[ProbeResult]:
    """One ProbeResult per row of ``positions`` (N, 3), as bake_probe would give each (see the module's
    docstring for the face-size search). ``scene`` may be None when ``renderer`` holds the splats.
    ``keep_radiance=False`` leaves ProbeResult.radiance None where nothing else needs it (a grid keeps SH only).
    SH orders other than 2 are not batched: use bake_probe."""
    s = settings if isinstance(settings, ProbeSettings) else ProbeSettings(**(settings or {}))
    method = check_settings(s)
    if s.sh_order != 2:
        raise BadSetting("sh_order", s.sh_order, f"SH order {s.sh_order}: batched probes keep order-2 SH; "
                                                 "use bake_probe for other orders")
    if not s.irradiance_size:
        raise BadSetting("irradiance_size", s.irradiance_size, "irradiance size 0 (from the tolerance) is chosen "
                                                               "probe by probe: give batched probes a size (4-64), "
                                                               "or use bake_probe")
    if s.hole_fill == "environment" and hole_radiance is None:
        raise BadSetting("hole_fill", s.hole_fill, "hole fill 'environment' needs the environment's radiance "
                                                   "(bake_probes' hole_radiance); use mean, constant or black")
    if scene is None and renderer is None:
        raise ValueError("bake_probes without a scene needs a renderer holding the splats")
    pos = check_probe_positions(positions)
    ctx = renderer.ctx if renderer is not None else get_context()
    largest = largest_probe_face(ctx, len(pos)) if len(pos) > 1 else int(s.max_face_size)
    if (s.face_size or AUTO_FIRST_FACE) > largest:  # checked before anything is uploaded
        raise BadSetting("face_size", s.face_size, f"{len(pos)} probes of {s.face_size or AUTO_FIRST_FACE}^2 faces "
                                                   f"do not fit {ctx.device_name} at once: use faces of {largest}^2 or "
                                                   "less, or bake fewer probes per call")
    say = progress or (lambda _msg, _frac: None)
    t0 = time.perf_counter()
    r = renderer
    highlights = None
    if scene is not None and renderer is None:  # clipped splats gained before upload, as bake_probe does
        scene, highlights = gain_clipped_splats(scene, s.highlight_gain)
    try:
        if r is None:
            say(f"uploading {scene.count:,} splats", 0.0)
            r = SplatRenderer(scene, lod=s.lod == "auto")
        results = _bake(r, pos, s, method, say, hole_radiance, keep_radiance, largest, highlights)
    except Exception as e:
        from .limits import out_of_memory_advice
        n = scene.count if scene is not None else r.scene_count
        advice = out_of_memory_advice(e, f"baking {len(pos)} probes of {n:,} splats",
                                      "bake fewer probes at a time, with smaller faces, or from fewer splats")
        if advice is None:
            raise
        raise advice from None
    finally:
        if renderer is None and r is not None:
            r.close()
    wall = (time.perf_counter() - t0) * 1e3
    for p in results:
        p.timings_ms["bake_wall"] = wall
        p.timings_ms["bake_wall_per_probe"] = wall / len(results)
    say("done", 1.0)
    return results


def _bake(r: SplatRenderer, pos: np.ndarray, s: ProbeSettings, method: str, say, hole_radiance,
          keep_radiance: bool, largest: int, highlights: dict | None) -> list[ProbeResult]:
    lod_k = float(s.lod_k) if s.lod == "auto" and r.lod is not None else 0.0
    n = len(pos)

    def at(face: int, lod: float) -> _Batch:
        res = r.render_probes(pos, face, lod_k=lod, timestamps=True, wait=False)
        sh, irr, holes, tm = _filter_batch(res.frame, s, method)
        timings = {**{f"render_{k}": v for k, v in res.timings_ms.items()},
                   **{f"filter_{k}": v for k, v in tm.items()}}
        return _Batch(res.frame, sh, irr, holes, timings)

    trials: list[dict] = []
    plan: dict = {}
    models = ProbeModels(n)
    stage_ms: dict[str, float] = {}  # the batch's stages, wall and GPU (core/stage_times.py), on every probe
    times = StageTimes(r.ctx, stage_ms)
    with times.stage("render" if s.face_size else "search"):
        if s.face_size:
            face = int(s.face_size)
            say(f"rendering {n} probes at {face}x{face}", 0.1)
            b = at(face, lod_k)
        else:
            b, face, trials, plan, lod_k = choose_face(at, models, s, lod_k, say, largest)
            plan.update(face_size=face, irradiance_size=int(s.irradiance_size), method=method,
                        sh_order=s.sh_order, lod="auto" if lod_k > 0 else "off",
                        batch_estimated_error=plan["estimated_error"])
    frame, sh, irr, holes, timings = b.frame, b.sh, b.irradiance, b.holes, b.timings
    on_cube = (s.highlight_gain != 1 and highlights is None) or s.lights > 0  # needs each probe's radiance
    fills = s.hole_fill != "black" and bool(np.any(holes > 0))
    # A one-colour fill (mean, constant) of a batch with nothing else to change on its cubes is filled on the GPU
    # (probe/gpu_holes.py) before any cube is read: none is filled in numpy and uploaded again, and a batch that
    # keeps only SH and irradiance (a grid's nodes, Lighting Auto's measurement) reads none back
    fill_on_gpu = fills and s.hole_fill in GPU_FILLS and method in BATCH_METHODS and not on_cube
    with times.stage("holes and lights"):
        if fill_on_gpu:
            t0 = time.perf_counter()
            fill_values = (covered_means(sh, holes) if s.hole_fill == "mean" else
                           np.tile(np.asarray(s.hole_colour, np.float64), (n, 1)))
            with fill_frame_holes(frame, fill_values):  # one submission with the filter
                sh, irr, _, _ = _filter_batch(frame, s, method)
            fill_ms = (time.perf_counter() - t0) * 1e3
    with times.stage("radiance readback"):
        read = keep_radiance or s.glossy or (fills and not fill_on_gpu) or on_cube
        radiance = frame.read_probes() if read else [None] * n
    with times.stage("holes and lights"):
        out, again = [], []
        # the settings as a dict once a batch, each probe a copy (asdict per probe was 1 ms of an Auto bake's 14 of
        # host time on an H100); ``extra`` is the one mutable field
        settings = asdict(s)
        for k in range(n):
            p = ProbeResult(radiance=radiance[k], irradiance=irr[k], sh_coefficients=sh[k], settings={},
                            timings_ms={**timings, "gpu_per_probe": (timings.get("render_total", 0.0)
                                                                     + timings.get("filter_total", 0.0)) / n},
                            splat_count=r.scene_count, device=r.ctx.device_name, hole_fraction=float(holes[k]))
            p.highlights = highlights
            if fill_on_gpu:  # filled above: recorded as fill_holes would
                p.hole_fill = {"method": s.hole_fill, "value": [float(v) for v in fill_values[k]],
                               "fraction": float(holes[k])}
                p.timings_ms["hole_fill"] = fill_ms
            elif radiance[k] is not None:
                if light_from_radiance(p, s, r.colour_space, hole_radiance, highlights is not None):
                    again.append(p)
            else:  # nothing to fill (no holes, or black): recorded as fill_holes would
                p.hole_fill = {"method": s.hole_fill, "value": [0.0, 0.0, 0.0], "fraction": float(holes[k])}
            mine = dict(plan)
            if trials:  # this probe's own estimate at the shared face
                mine.update(estimated_error=models.models[k].estimate(face),
                            met=models.models[k].estimate(face) <= s.tolerance)
            p.settings.update({**settings, "extra": copy.deepcopy(settings["extra"]), "method_requested": s.method,
                               "method": method, "face_size": face,
                               "face_size_trials": trials, "converged": (not trials) or bool(plan.get("met")),
                               "tolerance_plan": mine, "probe_position": [float(x) for x in pos[k]],
                               "colour_space": r.colour_space, "batch": {"probes": n, "index": k}})
            out.append(p)
        # Probes whose radiance changed (holes filled, highlights, lights) are filtered again, all in one batch (as
        # bake_probe does one).
        if again:
            t0 = time.perf_counter()
            cubes = np.stack([np.asarray(p.radiance)[..., :3] for p in again])
            sh2, irr2, _, _ = _filter_cubes(cubes, s, method, r.ctx)
            for p, sh_k, irr_k in zip(again, sh2, irr2):
                p.sh_coefficients, p.irradiance = sh_k, irr_k
                p.timings_ms["hole_fill"] = (time.perf_counter() - t0) * 1e3
    for p in out:
        if s.glossy:
            with times.stage("glossy"):
                p.prefiltered, _ = gpu_ggx_prefilter(np.asarray(p.radiance), GLOSSY_ROUGHNESS, ctx=r.ctx)
            p.roughness = list(GLOSSY_ROUGHNESS)
        if not keep_radiance:
            p.radiance = None
    for p in out:
        p.timings_ms.update(stage_ms)
    return out
