"""GPU (Vulkan compute) versions of the probe filters; each mirrors a numpy reference in this package.

  gpu_sh_project        -> sh_project.project_cube (order 2)     shaders/probe_sh_project.comp
  gpu_sh_irradiance     -> sh_project.sh_irradiance (order 2)    shaders/probe_sh_irradiance.comp
  gpu_cosine_convolve   -> convolve.cosine_convolve              shaders/probe_convolve.comp
  gpu_box_irradiance    -> box.box_irradiance                    shaders/probe_downsample.comp + probe_cube_read.comp

Cubes travel as packed float32 RGB (alpha is split off first: holes are black, as in numpy). The SH
reduction runs per workgroup on the GPU; the last few dozen group partials are added on the host in
float64. Solid angles come from core.cubemap (float64, uploaded as float32), never recomputed in GLSL.
Each function returns (result, timings_ms) with GPU timestamps per stage where the device has them.
"""
from __future__ import annotations

import math

import numpy as np

from .. import cubemap
from ..vk import Buffer, Recorder, get_context
from ..vk.compute import groups, pack
from .sampling import split_alpha
from .sh_project import cosine_lobe_coefficients, window_factors

SH_GROUPS_MAX = 64  # workgroups of the SH reduction: enough to fill a GPU, few enough to sum on the host


def _rgb32(cube: np.ndarray) -> np.ndarray:
    rgb, _ = split_alpha(cube)
    if rgb.shape[3] != 3:
        raise ValueError(f"GPU probe filters take RGB(A) cubes, got {rgb.shape[3]} channels")
    return np.ascontiguousarray(rgb, np.float32)


def _upload(ctx, data: np.ndarray, name: str) -> Buffer:
    b = Buffer(ctx, data.nbytes, name)
    b.write(np.ascontiguousarray(data, np.float32))
    return b


def _read_cube(buf: Buffer, size: int) -> np.ndarray:
    return buf.read(np.float32, 6 * size * size * 3).reshape(6, size, size, 3).astype(np.float64)


def gpu_sh_project(cube: np.ndarray, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Order-2 SH coefficients (9, 3) of a radiance cube on the GPU."""
    ctx = ctx or get_context()
    rgb = _rgb32(cube)
    n = rgb.shape[1]
    n_groups = max(1, min(SH_GROUPS_MAX, -(-6 * n * n // 256)))
    src = _upload(ctx, rgb, "probe-radiance")
    omega = _upload(ctx, cubemap.texel_solid_angles(n), "probe-omega")
    part = Buffer(ctx, n_groups * 27 * 4, "probe-sh-partial")
    with Recorder(ctx, timestamps=True) as rec:
        rec.dispatch(ctx.pipeline("probe_sh_project", 3, 8), [src, omega, part], n_groups, pack("II", n, n_groups))
        rec.timestamp("sh_project")
    coeffs = part.read(np.float32, n_groups * 27).reshape(n_groups, 9, 3).astype(np.float64).sum(axis=0)
    for b in (src, omega, part):
        b.destroy()
    return coeffs, rec.timings_ms


def gpu_sh_irradiance(coeffs: np.ndarray, size: int, window: str = "none", window_width: float | None = None,
                      clamp: bool = True, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Irradiance cube (6, size, size, 3) of E/pi from order-2 radiance SH (9, 3), evaluated on the GPU."""
    ctx = ctx or get_context()
    if coeffs.shape != (9, 3):
        raise ValueError(f"GPU SH irradiance takes order-2 RGB coefficients (9, 3), got {coeffs.shape}")
    band = cosine_lobe_coefficients(2) / math.pi * window_factors(2, window, window_width)
    scaled = coeffs * np.repeat(band, [1, 3, 5])[:, None]
    cb = _upload(ctx, scaled, "probe-sh")
    out = Buffer(ctx, 6 * size * size * 3 * 4, "probe-irradiance")
    with Recorder(ctx, timestamps=True) as rec:
        rec.dispatch(ctx.pipeline("probe_sh_irradiance", 2, 8), [cb, out], groups(6 * size * size, 64, ctx),
                     pack("II", size, int(clamp)))
        rec.timestamp("sh_irradiance")
    irr = _read_cube(out, size)
    cb.destroy()
    out.destroy()
    return irr, rec.timings_ms


def gpu_cosine_convolve(cube: np.ndarray, size: int, phi_steps: int = 64, theta_steps: int = 16,
                        ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Cosine-convolved irradiance cube (6, size, size, 3) of E/pi on the GPU (see convolve.cosine_convolve)."""
    ctx = ctx or get_context()
    if phi_steps < 1 or theta_steps < 1:
        raise ValueError(f"convolution needs at least one step per angle, got phi={phi_steps} theta={theta_steps}")
    rgb = _rgb32(cube)
    src = _upload(ctx, rgb, "probe-radiance")
    out = Buffer(ctx, 6 * size * size * 3 * 4, "probe-irradiance")
    with Recorder(ctx, timestamps=True) as rec:
        rec.dispatch(ctx.pipeline("probe_convolve", 2, 16), [src, out], groups(6 * size * size, 64, ctx),
                     pack("IIII", rgb.shape[1], size, phi_steps, theta_steps))
        rec.timestamp("convolve")
    irr = _read_cube(out, size)
    src.destroy()
    out.destroy()
    return irr, rec.timings_ms


def gpu_box_irradiance(cube: np.ndarray, size: int, level_size: int | None = None,
                       ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Thesis box filter on the GPU: 2x2 solid-angle downsampling to level_size, then a bilinear read by normal."""
    ctx = ctx or get_context()
    rgb = _rgb32(cube)
    n = rgb.shape[1]
    level_size = size if level_size is None else level_size
    if level_size < 1 or n % level_size or (n // level_size) & (n // level_size - 1):
        raise ValueError(f"box filter: level size {level_size} must be the face size {n} divided by a power of 2")
    keep = [_upload(ctx, rgb, "probe-radiance")]
    down = ctx.pipeline("probe_downsample", 3, 4)
    with Recorder(ctx, timestamps=True) as rec:
        cur = n
        while cur > level_size:
            omega = _upload(ctx, cubemap.texel_solid_angles(cur), f"probe-omega-{cur}")
            dst = Buffer(ctx, 6 * (cur // 2) ** 2 * 3 * 4, f"probe-mip-{cur // 2}")
            rec.dispatch(down, [keep[-1], omega, dst], groups(6 * (cur // 2) ** 2, 64, ctx), pack("I", cur))
            keep += [omega, dst]
            cur //= 2
        rec.timestamp("downsample")
        out = Buffer(ctx, 6 * size * size * 3 * 4, "probe-irradiance")
        keep.append(out)
        rec.dispatch(ctx.pipeline("probe_cube_read", 2, 8), [keep[-2], out], groups(6 * size * size, 64, ctx),
                     pack("II", cur, size))
        rec.timestamp("read")
    irr = _read_cube(out, size)
    for b in keep:
        b.destroy()
    return irr, rec.timings_ms
