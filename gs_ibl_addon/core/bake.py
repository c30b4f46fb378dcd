"""Bake a light probe: splats -> radiance cubemap (GPU) -> irradiance (GPU filter) -> ProbeResult.

``auto`` models no more than the probe needs, measured on the probe itself. Irradiance is a low-pass of the
radiance, so its error at face size N is about how much it still changes when the faces are doubled: starting at
32^2 faces, the cube is re-rendered at twice the size until the irradiance moves by less than the tolerance
(relative RMS), and the finer of the last two is kept. The filter is the exact texel integral on the GPU
(docs/accuracy.md: it costs about what SH projection costs and has neither SH's ringing nor the cosine
convolution's sampling noise); the 9 SH coefficients are still computed and stored in probe.json.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from .probe import ProbeResult, filter_probe
from .probe.ggx import DEFAULT_ROUGHNESS as GLOSSY_ROUGHNESS
from .probe.gpu_filters import gpu_ggx_prefilter
from .render.renderer import SplatRenderer
from .render.views import ViewBatch
from .scene import SplatScene

METHOD_ALIASES = {"auto": "exact", "sh": "sh", "conv": "convolve", "convolve": "convolve", "box": "box",
                  "exact": "exact"}
AUTO_FIRST_FACE = 32
AUTO_MAX_FACE = 1024


@dataclass
class ProbeSettings:
    method: str = "auto"  # auto | sh | conv | box | exact
    face_size: int = 0  # radiance face size; 0 = the smallest whose irradiance has converged to the tolerance
    irradiance_size: int = 16  # irradiance cube face size (lat-long output is 4x as wide)
    tolerance: float = 0.01  # relative RMS irradiance change that ends the face-size search
    sh_order: int = 2
    glossy: bool = False  # also GGX prefiltered radiance for glossy surfaces (slower)
    max_face_size: int = AUTO_MAX_FACE
    extra: dict = field(default_factory=dict)  # passed through to filter_probe (sample counts, windows...)


def default_probe_position(scene: SplatScene) -> np.ndarray:
    """Opacity-weighted centre of mass of the splats (inside any enclosing capture such as a room)."""
    if scene.count == 0:
        return np.zeros(3)
    w = scene.opacities.astype(np.float64)
    return (scene.positions.astype(np.float64) * w[:, None]).sum(0) / max(w.sum(), 1e-12)


def relative_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS of a - b over the RMS of b (all channels pooled)."""
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(np.sqrt(np.mean(b ** 2)), 1e-12))


def _search_and_filter(r: SplatRenderer, splat_count: int, pos: np.ndarray, s: ProbeSettings, method: str,
                       say: Callable[[str, float], None]) -> ProbeResult:
    """Render (and, with face size 0, search the face size), filter, and add the glossy maps when asked."""
    def probe_at(face: int) -> ProbeResult:
        res = r.render(ViewBatch.cubemap(pos, face), timestamps=True)
        timings = {f"render_{k}": v for k, v in res.timings_ms.items()}
        return filter_probe(np.stack(res.images), irradiance_size=s.irradiance_size, method=method,
                            sh_order=s.sh_order, roughness=None, timings_ms=timings, use_gpu=True, vk_context=r.ctx,
                            splat_count=splat_count, device=r.ctx.device_name, **s.extra)

    trials: list[dict] = []
    if s.face_size:
        face = int(s.face_size)
        say(f"rendering a {face}x{face} cubemap", 0.2)
        result = probe_at(face)
    else:
        face = AUTO_FIRST_FACE
        say(f"rendering a {face}x{face} cubemap", 0.1)
        result = probe_at(face)
        trials.append({"face_size": face, "change": None})
        while face < s.max_face_size:
            face *= 2
            finer = probe_at(face)
            change = relative_rms(result.irradiance, finer.irradiance)
            trials.append({"face_size": face, "change": change})
            say(f"{face}x{face}: irradiance moved {100 * change:.2f}% from {face // 2}x{face // 2}",
                min(0.8, 0.1 + 0.1 * len(trials)))
            result = finer
            if change <= s.tolerance:
                break
    if s.glossy:
        say("prefiltering glossy maps", 0.85)
        result.prefiltered, ggx_ms = gpu_ggx_prefilter(np.asarray(result.radiance), GLOSSY_ROUGHNESS, ctx=r.ctx)
        result.roughness = list(GLOSSY_ROUGHNESS)
        result.timings_ms["ggx"] = ggx_ms.get("total", 0.0)
    result.settings.update({**asdict(s), "method_requested": s.method, "method": method, "face_size": face,
                            "face_size_trials": trials, "converged": (not trials) or
                            (trials[-1]["change"] is not None and trials[-1]["change"] <= s.tolerance),
                            "probe_position": [float(x) for x in pos]})
    return result


def bake_probe(scene: SplatScene | None, probe_position=None, settings: ProbeSettings | dict | None = None,
               renderer: SplatRenderer | None = None,
               progress: Callable[[str, float], None] | None = None) -> ProbeResult:
    """Render the probe's radiance cubemap from the splats and filter it into irradiance (and optionally GGX).

    ``scene`` may be None when ``renderer`` already holds the splats and ``probe_position`` is given: a caller that
    keeps splats on the GPU (Blender's splat_cache) then needs no CPU copy of them.
    """
    s = settings if isinstance(settings, ProbeSettings) else ProbeSettings(**(settings or {}))
    method = METHOD_ALIASES.get(str(s.method).lower())
    if method is None:
        raise ValueError(f"unknown irradiance method {s.method!r}: use one of auto, sh, conv, box, exact")
    if int(s.face_size) < 0 or int(s.irradiance_size) < 1:
        raise ValueError(f"face size {s.face_size} must be 0 (search) or more, irradiance size "
                         f"{s.irradiance_size} 1 or more")
    if not 0 < s.tolerance < 1:
        raise ValueError(f"tolerance {s.tolerance} must be a fraction between 0 and 1 (0.01 = 1%)")
    if scene is None and (renderer is None or probe_position is None):
        raise ValueError("bake_probe without a scene needs both a renderer holding the splats and a probe position")
    pos = default_probe_position(scene) if probe_position is None else np.asarray(probe_position, np.float64)
    say = progress or (lambda _msg, _frac: None)
    t0 = time.perf_counter()
    r = renderer
    if r is None:
        say(f"uploading {scene.count:,} splats", 0.0)
        r = SplatRenderer(scene)
    try:
        result = _search_and_filter(r, r.scene_count, pos, s, method, say)
    finally:
        if renderer is None:  # ours: give its GPU buffers back now, not whenever Python collects it
            r.close()
    result.timings_ms["bake_wall"] = (time.perf_counter() - t0) * 1e3
    say("done", 1.0)
    return result
