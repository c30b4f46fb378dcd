"""Bake many probes of one scene at once: N positions -> N ProbeResults from one render and one filter submission.

The splats are uploaded once and every probe is rendered in the same submission (SplatRenderer.render_probes); the
exact irradiance (or the order-2 SH) of all of them is one more submission over the whole frame
(gpu_filters.filter_probes); only the SH, the irradiance and the hole fractions are read back, and the radiance
only when it is kept, has holes to fill, or feeds the glossy maps. Each probe's result is what bake_probe gives at
its position with the same face size (tests/test_multi_probe.py).

The one difference from bake_probe is the face-size search (face_size 0): the batch doubles the faces of all
probes together until every probe's irradiance moved by less than the tolerance, so all probes share the face size
the slowest-converging one needs (a grid or per-object probes are compared with each other: one resolution is
what they should have anyway). Methods "convolve" and "box" render in one batch and filter probe by probe.
"""
from __future__ import annotations

import time
from dataclasses import asdict
from typing import Callable

import numpy as np

from .bake import BadSetting, ProbeSettings, check_settings, relative_rms
from .probe import ProbeResult, filter_probe
from .probe.ggx import DEFAULT_ROUGHNESS as GLOSSY_ROUGHNESS
from .probe.gpu_filters import BATCH_METHODS, filter_probes, gpu_ggx_prefilter
from .probe.holes import fill_holes
from .render.renderer import SplatRenderer, largest_probe_face
from .scene import SplatScene
from .settings import AUTO_FIRST_FACE
from .vk import get_context


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
    try:
        if r is None:
            say(f"uploading {scene.count:,} splats", 0.0)
            r = SplatRenderer(scene, lod=s.lod == "auto")
        results = _bake(r, pos, s, method, say, hole_radiance, keep_radiance, largest)
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
          keep_radiance: bool, largest: int) -> list[ProbeResult]:
    lod_k = float(s.lod_k) if s.lod == "auto" and r.lod is not None else 0.0
    n = len(pos)

    def at(face: int):
        res = r.render_probes(pos, face, lod_k=lod_k, timestamps=True, wait=False)
        sh, irr, holes, tm = _filter_batch(res.frame, s, method)
        timings = {**{f"render_{k}": v for k, v in res.timings_ms.items()},
                   **{f"filter_{k}": v for k, v in tm.items()}}
        return res.frame, sh, irr, holes, timings

    trials: list[dict] = []
    face = int(s.face_size) or AUTO_FIRST_FACE
    say(f"rendering {n} probes at {face}x{face}", 0.1)
    frame, sh, irr, holes, timings = at(face)
    if not s.face_size:
        trials.append({"face_size": face, "change": None})
        while face < min(s.max_face_size, largest):  # the search stops where the batch's frame would not fit
            face *= 2
            frame, sh2, irr2, holes, timings = at(face)
            change = max(relative_rms(a, b) for a, b in zip(irr, irr2))
            trials.append({"face_size": face, "change": change})
            say(f"{face}x{face}: irradiance moved {100 * change:.2f}% at most from {face // 2}x{face // 2}",
                min(0.8, 0.1 + 0.1 * len(trials)))
            sh, irr = sh2, irr2
            if change <= s.tolerance:
                break
    fills = s.hole_fill != "black" and bool(np.any(holes > 0))
    radiance = frame.read_probes() if (keep_radiance or s.glossy or fills) else [None] * n
    converged = (not trials) or (trials[-1]["change"] is not None and trials[-1]["change"] <= s.tolerance)
    out = []
    for k in range(n):
        p = ProbeResult(radiance=radiance[k], irradiance=irr[k], sh_coefficients=sh[k], settings={},
                        timings_ms={**timings, "gpu_per_probe": (timings.get("render_total", 0.0)
                                                                 + timings.get("filter_total", 0.0)) / n},
                        splat_count=r.scene_count, device=r.ctx.device_name, hole_fraction=float(holes[k]))
        if radiance[k] is not None:
            p.radiance, p.hole_fill = fill_holes(radiance[k], s.hole_fill, s.hole_colour, hole_radiance)
        else:  # nothing to fill (no holes, or black): recorded as fill_holes would
            p.hole_fill = {"method": s.hole_fill, "value": [0.0, 0.0, 0.0], "fraction": float(holes[k])}
        p.settings.update({**asdict(s), "method_requested": s.method, "method": method, "face_size": face,
                           "face_size_trials": trials, "converged": converged,
                           "probe_position": [float(x) for x in pos[k]], "colour_space": r.colour_space,
                           "batch": {"probes": n, "index": k}})
        out.append(p)
    # Probes with holes are filtered again from their filled radiance, all in one batch (as bake_probe does one).
    filled = [p for p in out if s.hole_fill != "black" and p.hole_fill["fraction"] > 0]
    if filled:
        t0 = time.perf_counter()
        again = _filter_cubes(np.stack([p.radiance for p in filled]), s, method, r.ctx)
        for p, sh_k, irr_k in zip(filled, again[0], again[1]):
            p.sh_coefficients, p.irradiance = sh_k, irr_k
            p.timings_ms["hole_fill"] = (time.perf_counter() - t0) * 1e3
    for p in out:
        if s.glossy:
            p.prefiltered, _ = gpu_ggx_prefilter(np.asarray(p.radiance), GLOSSY_ROUGHNESS, ctx=r.ctx)
            p.roughness = list(GLOSSY_ROUGHNESS)
        if not keep_radiance:
            p.radiance = None
    return out
