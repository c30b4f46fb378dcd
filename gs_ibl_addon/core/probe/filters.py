"""One call from a radiance cube to a ProbeResult with the chosen irradiance method, timed.

``use_gpu=False`` runs the numpy implementations (the references). ``use_gpu=True`` uploads the cube once and runs
every stage that has a Vulkan version on the GPU (gpu_filters: SH order 2 projection and evaluation, cosine
convolution, box, exact, GGX prefiltered maps); SH of another order stays in numpy. Timings are in milliseconds:
GPU stages report GPU timestamps (``timings_ms['irradiance']`` = the filter's GPU time, with per-stage detail under
``irradiance.<stage>``), numpy stages wall time; ``settings['stage_devices']`` says which ran where.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .box import box_irradiance
from .convolve import cosine_convolve
from .ggx import DEFAULT_ROUGHNESS, ggx_prefilter
from .reference import exact_irradiance_cube
from .result import ProbeResult
from .sampling import split_alpha
from .sh_project import project_cube, sh_irradiance
from .. import cubemap

METHODS = ("sh", "convolve", "box", "exact")
DEFAULT_DOWNSAMPLE_TO = 32  # exact method: integrate a <= 32^2-face copy (rel RMS loss ~2e-4, docs/accuracy.md)


@dataclass(frozen=True, kw_only=True)
class _Params:
    """What the irradiance and GGX stages are asked for (filter_probe's arguments, minus where they run)."""
    size: int
    method: str
    sh_order: int
    sh_window: str
    phi_steps: int
    theta_steps: int
    box_level_size: int
    downsample_to: int | None
    roughness: tuple[float, ...] | None
    ggx_samples: int


class _Stages:
    """Runs filter stages, recording each one's time (ms) under its name and where it ran (cpu/gpu)."""

    def __init__(self, timings: dict[str, float]) -> None:
        self.timings = timings
        self.devices: dict[str, str] = {}

    def cpu(self, name: str, fn, *args, **kw):
        t0 = time.perf_counter()
        out = fn(*args, **kw)
        self.timings[name] = (time.perf_counter() - t0) * 1e3
        self.devices[name] = "cpu"
        return out

    def gpu(self, name: str, fn, *args, **kw):
        """fn returns (result, GPU timings): the stage's time is the GPU's where the device has timestamps."""
        t0 = time.perf_counter()
        out, tm = fn(*args, **kw)
        wall = (time.perf_counter() - t0) * 1e3
        self.timings[name] = tm.get("total", wall)
        self.timings[f"{name}_wall"] = wall
        self.timings.update({f"{name}.{k}": v for k, v in tm.items() if k != "total"})
        self.devices[name] = "gpu"
        return out


def filter_probe(radiance: np.ndarray, irradiance_size: int = 16, method: str = "sh", sh_order: int = 2,
                 sh_window: str = "none", phi_steps: int = 64, theta_steps: int = 16, box_level_size: int = 1,
                 downsample_to: int | None = DEFAULT_DOWNSAMPLE_TO,
                 roughness: tuple[float, ...] | None = DEFAULT_ROUGHNESS, ggx_samples: int = 256,
                 use_gpu: bool = False, vk_context=None, **result_fields: Any) -> ProbeResult:
    """Filter a (6, N, N, 3|4) radiance cube; SH coefficients are always computed (cheap, and stored in probe.json).

    roughness=None skips the GGX maps. downsample_to (exact method) halves the faces down to that size before
    integrating (None: every texel). vk_context: the Vulkan context for use_gpu (default: the shared one).
    Extra keyword arguments (splat_count, device, timings_ms, settings, ...) go to the ProbeResult.
    """
    if method not in METHODS:
        raise ValueError(f"irradiance method must be one of {METHODS}, got {method!r}")
    stages = _Stages(dict(result_fields.pop("timings_ms", {})))
    rgb, hole = split_alpha(radiance)
    p = _Params(size=irradiance_size, method=method, sh_order=sh_order, sh_window=sh_window, phi_steps=phi_steps,
                theta_steps=theta_steps, box_level_size=box_level_size, downsample_to=downsample_to,
                roughness=None if roughness is None else tuple(roughness), ggx_samples=ggx_samples)
    if use_gpu:
        coeffs, irr, pre = _filter_gpu(rgb, p, vk_context, stages)
    else:
        coeffs, irr, pre = _filter_cpu(rgb, p, stages)
    settings = {"method": method, "irradiance_size": irradiance_size, "sh_order": sh_order, "sh_window": sh_window,
                "phi_steps": phi_steps, "theta_steps": theta_steps, "box_level_size": box_level_size,
                "downsample_to": downsample_to, "ggx_samples": ggx_samples, "radiance_face_size": int(rgb.shape[1]),
                "use_gpu": bool(use_gpu), "stage_devices": stages.devices}
    settings.update(result_fields.pop("settings", {}))
    return ProbeResult(radiance=np.asarray(radiance), irradiance=irr, sh_coefficients=coeffs, prefiltered=pre,
                       roughness=[] if roughness is None else list(roughness), settings=settings,
                       timings_ms=stages.timings, hole_fraction=hole, **result_fields)


def _filter_cpu(rgb: np.ndarray, p: _Params, stages: _Stages) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    coeffs = stages.cpu("sh_project", project_cube, rgb, p.sh_order)
    if p.method == "sh":
        irr = stages.cpu("irradiance", sh_irradiance, coeffs, cubemap.face_directions(p.size), p.sh_window)
    elif p.method == "convolve":
        irr = stages.cpu("irradiance", cosine_convolve, rgb, p.size, p.phi_steps, p.theta_steps)
    elif p.method == "box":
        irr = stages.cpu("irradiance", box_irradiance, rgb, p.size, p.box_level_size)
    else:
        irr = stages.cpu("irradiance", exact_irradiance_cube, rgb, p.size, p.downsample_to)
    pre = [] if p.roughness is None else stages.cpu("ggx", ggx_prefilter, rgb, p.roughness, None, p.ggx_samples)
    return coeffs, irr, pre


def _filter_gpu(rgb: np.ndarray, p: _Params, ctx, stages: _Stages
                ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    from . import gpu_filters as g  # Vulkan is imported only when the GPU path is asked for

    t0 = time.perf_counter()
    cube = g.upload_cube(rgb, ctx)
    stages.timings["upload"] = (time.perf_counter() - t0) * 1e3
    try:
        coeffs = (stages.gpu("sh_project", g.gpu_sh_project, cube) if p.sh_order == 2
                  else stages.cpu("sh_project", project_cube, rgb, p.sh_order))
        if p.method == "sh":
            irr = (stages.gpu("irradiance", g.gpu_sh_irradiance, coeffs, p.size, p.sh_window, ctx=cube.ctx)
                   if p.sh_order == 2 else
                   stages.cpu("irradiance", sh_irradiance, coeffs, cubemap.face_directions(p.size), p.sh_window))
        elif p.method == "convolve":
            irr = stages.gpu("irradiance", g.gpu_cosine_convolve, cube, p.size, p.phi_steps, p.theta_steps)
        elif p.method == "box":
            irr = stages.gpu("irradiance", g.gpu_box_irradiance, cube, p.size, p.box_level_size)
        else:
            irr = stages.gpu("irradiance", g.gpu_exact_irradiance, cube, p.size, p.downsample_to)
        pre = ([] if p.roughness is None
               else stages.gpu("ggx", g.gpu_ggx_prefilter, cube, p.roughness, None, p.ggx_samples))
    finally:
        cube.close()
    return coeffs, irr, pre
