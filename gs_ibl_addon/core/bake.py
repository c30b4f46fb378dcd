"""Bake a light probe: splats -> radiance cubemap (GPU) -> irradiance by the chosen filter -> ProbeResult.

``auto`` models no more than the scene needs: it projects the radiance onto order-2 SH (9 numbers per channel,
the cheapest smooth representation), measures that irradiance against the exact integral of this very cube at a
coarse set of normals, and keeps SH only when the measured error is within the tolerance; otherwise it integrates
the cube exactly (every texel, exact solid angles), which is cheap at probe face sizes and has none of the
sampling noise of the cosine convolution. The face size is picked from the tolerance (see docs/accuracy.md for the measurements).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from . import cubemap
from .probe import ProbeResult, filter_probe
from .probe.box import downsample_cube
from .probe.reference import exact_irradiance
from .probe.sh_project import project_cube, sh_irradiance
from .render.renderer import SplatRenderer
from .render.views import ViewBatch
from .scene import SplatScene

METHOD_ALIASES = {"auto": "auto", "sh": "sh", "conv": "convolve", "convolve": "convolve", "box": "box",
                  "exact": "exact"}


@dataclass
class ProbeSettings:
    method: str = "auto"  # auto | sh | conv | box | exact
    face_size: int = 0  # radiance face size; 0 = chosen from the tolerance
    irradiance_size: int = 16  # irradiance cube face size (lat-long output is 4x as wide)
    tolerance: float = 0.01  # relative RMS irradiance error that auto may spend
    sh_order: int = 2
    glossy: bool = False  # also GGX prefiltered radiance for glossy surfaces (slower)
    extra: dict = field(default_factory=dict)  # passed through to filter_probe (sample counts, windows...)


def face_size_for(tolerance: float) -> int:
    """Radiance face size for an irradiance tolerance: irradiance is a low-pass of the radiance, so small faces
    carry it; the table comes from benchmarks/accuracy_bench.py (docs/accuracy.md)."""
    if tolerance >= 0.05:
        return 32
    if tolerance >= 0.005:
        return 64
    return 128


def default_probe_position(scene: SplatScene) -> np.ndarray:
    """Opacity-weighted centre of mass of the splats (inside any enclosing capture such as a room)."""
    if scene.count == 0:
        return np.zeros(3)
    w = scene.opacities.astype(np.float64)
    return (scene.positions.astype(np.float64) * w[:, None]).sum(0) / max(w.sum(), 1e-12)


def sh_error_estimate(radiance: np.ndarray, order: int = 2, check_size: int = 8) -> float:
    """Relative RMS error of order-``order`` SH irradiance against the exact integral of the same cube, measured at
    6 x check_size^2 normals (from a cube downsampled to at most 32^2 faces, which keeps the integral exact to
    well under 0.1% for irradiance)."""
    rgb = radiance[..., :3] if radiance.shape[-1] == 4 else radiance
    while rgb.shape[1] > 32 and rgb.shape[1] % 2 == 0:
        rgb = downsample_cube(rgb)
    normals = cubemap.face_directions(check_size)
    exact = exact_irradiance(rgb, normals)
    approx = sh_irradiance(project_cube(rgb, order), normals)
    denom = np.sqrt(np.mean(exact ** 2))
    return float(np.sqrt(np.mean((approx - exact) ** 2)) / max(denom, 1e-12))


def bake_probe(scene: SplatScene, probe_position=None, settings: ProbeSettings | dict | None = None,
               renderer: SplatRenderer | None = None,
               progress: Callable[[str, float], None] | None = None) -> ProbeResult:
    """Render the probe's radiance cubemap from the splats and filter it into irradiance (and optionally GGX)."""
    s = settings if isinstance(settings, ProbeSettings) else ProbeSettings(**(settings or {}))
    method = METHOD_ALIASES.get(str(s.method).lower())
    if method is None:
        raise ValueError(f"unknown irradiance method {s.method!r}: use one of auto, sh, conv, box, exact")
    if not 0 < s.tolerance < 1:
        raise ValueError(f"tolerance {s.tolerance} must be a fraction between 0 and 1 (0.01 = 1%)")
    face = int(s.face_size) or face_size_for(s.tolerance)
    pos = default_probe_position(scene) if probe_position is None else np.asarray(probe_position, np.float64)
    say = progress or (lambda _msg, _frac: None)
    t0 = time.perf_counter()
    say(f"uploading {scene.count:,} splats", 0.0)
    r = renderer or SplatRenderer(scene)
    say(f"rendering a {face}x{face} cubemap", 0.2)
    res = r.render(ViewBatch.cubemap(pos, face), timestamps=True)
    cube = np.stack(res.images)
    timings = {f"render_{k}": v for k, v in res.timings_ms.items()}
    chosen = method
    estimate = None
    if method == "auto":
        say("measuring SH accuracy on this probe", 0.6)
        estimate = sh_error_estimate(cube, s.sh_order)
        chosen = "sh" if estimate <= s.tolerance else "exact"
    say(f"filtering ({chosen})", 0.7)
    settings_out = {**asdict(s), "method_requested": s.method, "method": chosen, "face_size": face,
                    "probe_position": [float(x) for x in pos], "sh_error_estimate": estimate}
    result = filter_probe(cube, irradiance_size=s.irradiance_size, method=chosen, sh_order=s.sh_order,
                          roughness=None if not s.glossy else (0.25, 0.5, 0.75, 1.0), timings_ms=timings,
                          settings=settings_out, splat_count=scene.count, device=r.ctx.device_name, **s.extra)
    result.timings_ms["bake_wall"] = (time.perf_counter() - t0) * 1e3
    say("done", 1.0)
    return result
