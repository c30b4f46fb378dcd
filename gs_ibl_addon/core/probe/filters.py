"""One call from a radiance cube to a ProbeResult with the chosen irradiance method (numpy path), timed."""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from .box import box_irradiance
from .convolve import cosine_convolve
from .ggx import DEFAULT_ROUGHNESS, ggx_prefilter
from .result import ProbeResult
from .sampling import split_alpha
from .sh_project import project_cube, sh_irradiance
from .. import cubemap

METHODS = ("sh", "convolve", "box", "exact")


def filter_probe(radiance: np.ndarray, irradiance_size: int = 16, method: str = "sh", sh_order: int = 2,
                 sh_window: str = "none", phi_steps: int = 64, theta_steps: int = 16, box_level_size: int = 1,
                 roughness: tuple[float, ...] | None = DEFAULT_ROUGHNESS, ggx_samples: int = 256,
                 **result_fields: Any) -> ProbeResult:
    """Filter a (6, N, N, 3|4) radiance cube; SH coefficients are always computed (cheap, and stored in probe.json).

    roughness=None skips the GGX maps. Extra keyword arguments (splat_count, device, ...) go to the ProbeResult.
    """
    if method not in METHODS:
        raise ValueError(f"irradiance method must be one of {METHODS}, got {method!r}")
    timings: dict[str, float] = dict(result_fields.pop("timings_ms", {}))

    def timed(name: str, fn, *args, **kw):
        t0 = time.perf_counter()
        out = fn(*args, **kw)
        timings[name] = (time.perf_counter() - t0) * 1e3
        return out

    rgb, hole = split_alpha(radiance)
    coeffs = timed("sh_project", project_cube, rgb, sh_order)
    normals = cubemap.face_directions(irradiance_size)
    if method == "sh":
        irr = timed("irradiance", sh_irradiance, coeffs, normals, sh_window)
    elif method == "convolve":
        irr = timed("irradiance", cosine_convolve, rgb, irradiance_size, phi_steps, theta_steps)
    elif method == "box":
        irr = timed("irradiance", box_irradiance, rgb, irradiance_size, box_level_size)
    else:
        from .reference import exact_irradiance
        irr = timed("irradiance", exact_irradiance, rgb, normals)
    pre = [] if roughness is None else timed("ggx", ggx_prefilter, rgb, tuple(roughness), None, ggx_samples)
    settings = {"method": method, "irradiance_size": irradiance_size, "sh_order": sh_order, "sh_window": sh_window,
                "phi_steps": phi_steps, "theta_steps": theta_steps, "box_level_size": box_level_size,
                "ggx_samples": ggx_samples, "radiance_face_size": int(rgb.shape[1])}
    settings.update(result_fields.pop("settings", {}))
    return ProbeResult(radiance=np.asarray(radiance), irradiance=irr, sh_coefficients=coeffs, prefiltered=pre,
                       roughness=[] if roughness is None else list(roughness), settings=settings,
                       timings_ms=timings, hole_fraction=hole, **result_fields)
