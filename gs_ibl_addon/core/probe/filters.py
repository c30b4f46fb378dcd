"""One call from a radiance cube to a ProbeResult with the chosen irradiance method, timed.

``use_gpu=False`` runs the numpy implementations (the references). ``use_gpu=True`` uploads the cube once and runs
every stage that has a Vulkan version on the GPU (gpu_filters: SH order 2 projection and evaluation, cosine
convolution, box, exact, GGX prefiltered maps); SH of another order stays in numpy. Timings are in milliseconds:
GPU stages report GPU timestamps (``timings_ms['irradiance']`` = the filter's GPU time, with per-stage detail under
``irradiance.<stage>``), numpy stages wall time; ``settings['stage_devices']`` says which ran where.
"""
from __future__ import annotations

import time
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
    timings: dict[str, float] = dict(result_fields.pop("timings_ms", {}))
    devices: dict[str, str] = {}

    def timed(name: str, fn, *args, **kw):
        t0 = time.perf_counter()
        out = fn(*args, **kw)
        timings[name] = (time.perf_counter() - t0) * 1e3
        devices[name] = "cpu"
        return out

    rgb, hole = split_alpha(radiance)
    rough = None if roughness is None else tuple(roughness)
    if use_gpu:
        coeffs, irr, pre = _filter_gpu(rgb, irradiance_size, method, sh_order, sh_window, phi_steps, theta_steps,
                                       box_level_size, downsample_to, rough, ggx_samples, vk_context, timings,
                                       devices, timed)
    else:
        coeffs = timed("sh_project", project_cube, rgb, sh_order)
        normals = cubemap.face_directions(irradiance_size)
        if method == "sh":
            irr = timed("irradiance", sh_irradiance, coeffs, normals, sh_window)
        elif method == "convolve":
            irr = timed("irradiance", cosine_convolve, rgb, irradiance_size, phi_steps, theta_steps)
        elif method == "box":
            irr = timed("irradiance", box_irradiance, rgb, irradiance_size, box_level_size)
        else:
            irr = timed("irradiance", exact_irradiance_cube, rgb, irradiance_size, downsample_to)
        pre = [] if rough is None else timed("ggx", ggx_prefilter, rgb, rough, None, ggx_samples)
    settings = {"method": method, "irradiance_size": irradiance_size, "sh_order": sh_order, "sh_window": sh_window,
                "phi_steps": phi_steps, "theta_steps": theta_steps, "box_level_size": box_level_size,
                "downsample_to": downsample_to, "ggx_samples": ggx_samples, "radiance_face_size": int(rgb.shape[1]),
                "use_gpu": bool(use_gpu), "stage_devices": devices}
    settings.update(result_fields.pop("settings", {}))
    return ProbeResult(radiance=np.asarray(radiance), irradiance=irr, sh_coefficients=coeffs, prefiltered=pre,
                       roughness=[] if roughness is None else list(roughness), settings=settings,
                       timings_ms=timings, hole_fraction=hole, **result_fields)


def _filter_gpu(rgb, size, method, sh_order, sh_window, phi_steps, theta_steps, box_level_size, downsample_to,
                roughness, ggx_samples, ctx, timings, devices,
                timed) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    from . import gpu_filters as g  # Vulkan is imported only when the GPU path is asked for

    t0 = time.perf_counter()
    cube = g.upload_cube(rgb, ctx)
    timings["upload"] = (time.perf_counter() - t0) * 1e3

    def gpu(name: str, fn, *args, **kw):
        t1 = time.perf_counter()
        out, tm = fn(*args, **kw)
        wall = (time.perf_counter() - t1) * 1e3
        timings[name] = tm.get("total", wall)  # GPU time; wall time where the device has no timestamps
        timings[f"{name}_wall"] = wall
        timings.update({f"{name}.{k}": v for k, v in tm.items() if k != "total"})
        devices[name] = "gpu"
        return out

    try:
        coeffs = (gpu("sh_project", g.gpu_sh_project, cube) if sh_order == 2
                  else timed("sh_project", project_cube, rgb, sh_order))
        if method == "sh":
            irr = (gpu("irradiance", g.gpu_sh_irradiance, coeffs, size, sh_window, ctx=cube.ctx) if sh_order == 2
                   else timed("irradiance", sh_irradiance, coeffs, cubemap.face_directions(size), sh_window))
        elif method == "convolve":
            irr = gpu("irradiance", g.gpu_cosine_convolve, cube, size, phi_steps, theta_steps)
        elif method == "box":
            irr = gpu("irradiance", g.gpu_box_irradiance, cube, size, box_level_size)
        else:
            irr = gpu("irradiance", g.gpu_exact_irradiance, cube, size, downsample_to)
        pre = [] if roughness is None else gpu("ggx", g.gpu_ggx_prefilter, cube, roughness, None, ggx_samples)
    finally:
        cube.close()
    return coeffs, irr, pre
