"""GPU (Vulkan compute) versions of the probe filters; each mirrors a numpy reference in this package.

  gpu_sh_project        -> sh_project.project_cube (order 2)     shaders/probe_sh_project.comp
  gpu_sh_irradiance     -> sh_project.sh_irradiance (order 2)    shaders/probe_sh_irradiance.comp
  gpu_cosine_convolve   -> convolve.cosine_convolve              shaders/probe_convolve.comp
  gpu_box_irradiance    -> box.box_irradiance                    shaders/probe_downsample.comp + probe_cube_read.comp
  gpu_exact_irradiance  -> reference.exact_irradiance of          shaders/probe_downsample.comp + probe_integrate.comp
                           box.downsample_cube^k (downsample_to)
  gpu_ggx_prefilter     -> ggx.ggx_prefilter                      shaders/probe_downsample.comp + probe_ggx.comp

Cubes travel as packed float32 RGB (alpha is split off first: holes are black, as in numpy). Every filter takes
a numpy cube or a GpuCube (``upload_cube``): several filters of one cube then share one upload. The SH
reduction runs per workgroup on the GPU; the last few dozen group partials are added on the host in
float64. Solid angles come from core.cubemap (float64, uploaded as float32), never recomputed in GLSL; likewise
the GGX sample table (directions, weights, mip lods) comes from ggx.ggx_samples, so both paths share one sequence.
Each function returns (result, timings_ms) with GPU timestamps per stage where the device has them.
"""
from __future__ import annotations

import math

import numpy as np

from .. import cubemap
from ..vk import Buffer, Recorder, get_context
from ..vk.compute import groups, pack
from .ggx import DEFAULT_ROUGHNESS, ggx_samples
from .sampling import split_alpha
from .sh_project import cosine_lobe_coefficients, window_factors

SH_GROUPS_MAX = 64  # workgroups of the SH reduction: enough to fill a GPU, few enough to sum on the host


def _rgb32(cube: np.ndarray) -> np.ndarray:
    rgb, _ = split_alpha(cube)
    if rgb.shape[3] != 3:
        raise ValueError(f"GPU probe filters take RGB(A) cubes, got {rgb.shape[3]} channels")
    return np.ascontiguousarray(rgb, np.float32)


def _upload(ctx, data: np.ndarray, name: str) -> Buffer:
    a = np.ascontiguousarray(data, np.float32)
    b = Buffer(ctx, a.nbytes, name)
    b.write(a)
    return b


class GpuCube:
    """A radiance cube uploaded once (packed float32 RGB, holes black); pass it to any filter here instead of
    the numpy cube to skip the per-call upload. ``close()`` frees it."""

    def __init__(self, cube: np.ndarray, ctx=None) -> None:
        self.ctx = ctx or get_context()
        rgb = _rgb32(cube)
        self.size = int(rgb.shape[1])
        self.buffer = _upload(self.ctx, rgb, "probe-radiance")

    def close(self) -> None:
        self.buffer.destroy()


def upload_cube(cube: np.ndarray, ctx=None) -> GpuCube:
    return GpuCube(cube, ctx)


def _source(cube, ctx) -> tuple[object, Buffer, int, bool]:
    """(ctx, buffer, face size, owned): owned buffers are the caller's to destroy."""
    if isinstance(cube, GpuCube):
        return cube.ctx, cube.buffer, cube.size, False
    ctx = ctx or get_context()
    rgb = _rgb32(cube)
    return ctx, _upload(ctx, rgb, "probe-radiance"), int(rgb.shape[1]), True


def _downsample(ctx, rec: Recorder, src: Buffer, n: int, target: int, keep: list[Buffer]) -> tuple[Buffer, int]:
    """Record 2x2 solid-angle downsampling steps (box.downsample_cube) while the face is above target and even."""
    down = ctx.pipeline("probe_downsample", 3, 4)
    cur, buf = n, src
    while cur > target and cur % 2 == 0:
        omega = _upload(ctx, cubemap.texel_solid_angles(cur), f"probe-omega-{cur}")
        dst = Buffer(ctx, 6 * (cur // 2) ** 2 * 3 * 4, f"probe-mip-{cur // 2}")
        rec.dispatch(down, [buf, omega, dst], groups(6 * (cur // 2) ** 2, 64, ctx), pack("I", cur))
        keep += [omega, dst]
        buf, cur = dst, cur // 2
    return buf, cur


def _read_cube(buf: Buffer, size: int) -> np.ndarray:
    return buf.read(np.float32, 6 * size * size * 3).reshape(6, size, size, 3).astype(np.float64)


def gpu_sh_project(cube, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Order-2 SH coefficients (9, 3) of a radiance cube (numpy or GpuCube) on the GPU."""
    ctx, src, n, owned = _source(cube, ctx)
    n_groups = max(1, min(SH_GROUPS_MAX, -(-6 * n * n // 256)))
    omega = _upload(ctx, cubemap.texel_solid_angles(n), "probe-omega")
    part = Buffer(ctx, n_groups * 27 * 4, "probe-sh-partial")
    with Recorder(ctx, timestamps=True) as rec:
        rec.dispatch(ctx.pipeline("probe_sh_project", 3, 8), [src, omega, part], n_groups, pack("II", n, n_groups))
        rec.timestamp("sh_project")
    coeffs = part.read(np.float32, n_groups * 27).reshape(n_groups, 9, 3).astype(np.float64).sum(axis=0)
    for b in (omega, part) + ((src,) if owned else ()):
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


def gpu_cosine_convolve(cube, size: int, phi_steps: int = 64, theta_steps: int = 16,
                        ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Cosine-convolved irradiance cube (6, size, size, 3) of E/pi on the GPU (see convolve.cosine_convolve)."""
    if phi_steps < 1 or theta_steps < 1:
        raise ValueError(f"convolution needs at least one step per angle, got phi={phi_steps} theta={theta_steps}")
    ctx, src, n, owned = _source(cube, ctx)
    out = Buffer(ctx, 6 * size * size * 3 * 4, "probe-irradiance")
    with Recorder(ctx, timestamps=True) as rec:
        rec.dispatch(ctx.pipeline("probe_convolve", 2, 16), [src, out], groups(6 * size * size, 64, ctx),
                     pack("IIII", n, size, phi_steps, theta_steps))
        rec.timestamp("convolve")
    irr = _read_cube(out, size)
    if owned:
        src.destroy()
    out.destroy()
    return irr, rec.timings_ms


def gpu_box_irradiance(cube, size: int, level_size: int | None = None,
                       ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Thesis box filter on the GPU: 2x2 solid-angle downsampling to level_size, then a bilinear read by normal."""
    n = cube.size if isinstance(cube, GpuCube) else np.shape(cube)[1]
    level_size = size if level_size is None else level_size
    if level_size < 1 or n % level_size or (n // level_size) & (n // level_size - 1):
        raise ValueError(f"box filter: level size {level_size} must be the face size {n} divided by a power of 2")
    ctx, src, n, owned = _source(cube, ctx)
    keep: list[Buffer] = [src] if owned else []
    with Recorder(ctx, timestamps=True) as rec:
        small, cur = _downsample(ctx, rec, src, n, level_size, keep)
        rec.timestamp("downsample")
        out = Buffer(ctx, 6 * size * size * 3 * 4, "probe-irradiance")
        keep.append(out)
        rec.dispatch(ctx.pipeline("probe_cube_read", 2, 8), [small, out], groups(6 * size * size, 64, ctx),
                     pack("II", cur, size))
        rec.timestamp("read")
    irr = _read_cube(out, size)
    for b in keep:
        b.destroy()
    return irr, rec.timings_ms


def integration_size(face_size: int, downsample_to: int | None) -> int:
    """Face size the exact integral runs at: halved while above downsample_to and even (None: no downsampling)."""
    n = int(face_size)
    if downsample_to is not None:
        if downsample_to < 1:
            raise ValueError(f"exact irradiance: downsample_to must be >= 1 or None, got {downsample_to}")
        while n > downsample_to and n % 2 == 0:
            n //= 2
    return n


def gpu_exact_irradiance(cube, size: int, downsample_to: int | None = 32,
                         ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Exact irradiance cube (6, size, size, 3) of E/pi on the GPU: the cube is box-downsampled (solid-angle
    weighted, power-preserving) to downsample_to per face, then every texel is integrated for every output
    normal. numpy reference: reference.exact_irradiance(box.downsample_cube^k(cube), face_directions(size))."""
    ctx, src, n, owned = _source(cube, ctx)
    keep: list[Buffer] = [src] if owned else []
    k = integration_size(n, downsample_to)
    texels = np.concatenate([cubemap.face_directions(k).reshape(-1, 3),
                             np.tile(cubemap.texel_solid_angles(k).reshape(-1) / math.pi, 6)[:, None]], 1)
    tex = _upload(ctx, texels, "probe-texels")
    out = Buffer(ctx, 6 * size * size * 3 * 4, "probe-irradiance")
    keep += [tex, out]
    with Recorder(ctx, timestamps=True) as rec:
        small, cur = _downsample(ctx, rec, src, n, k, keep)
        rec.timestamp("downsample")
        rec.dispatch(ctx.pipeline("probe_integrate", 3, 8), [small, tex, out], groups(6 * size * size, 1, ctx),
                     pack("II", cur, size))
        rec.timestamp("integrate")
    irr = _read_cube(out, size)
    for b in keep:
        b.destroy()
    return irr, rec.timings_ms


def _mip_chain(ctx, rec: Recorder, src: Buffer, n: int, keep: list[Buffer]) -> tuple[Buffer, int]:
    """Record box.mip_chain into one buffer (level after level, packed RGB): (buffer, number of levels)."""
    sizes = [n]
    while sizes[-1] > 1 and sizes[-1] % 2 == 0:
        sizes.append(sizes[-1] // 2)
    chain = Buffer(ctx, sum(6 * s * s * 3 * 4 for s in sizes), "probe-mip-chain")
    keep.append(chain)
    rec.copy(src, chain, 6 * n * n * 3 * 4)
    down = ctx.pipeline("probe_downsample", 3, 4)
    cur, offset = src, 6 * n * n * 3 * 4
    for child, parent in zip(sizes, sizes[1:]):
        omega = _upload(ctx, cubemap.texel_solid_angles(child), f"probe-omega-{child}")
        dst = Buffer(ctx, 6 * parent * parent * 3 * 4, f"probe-mip-{parent}")
        rec.dispatch(down, [cur, omega, dst], groups(6 * parent * parent, 64, ctx), pack("I", child))
        rec.copy(dst, chain, dst.nbytes, 0, offset)
        keep += [omega, dst]
        cur, offset = dst, offset + dst.nbytes
    return chain, len(sizes)


def ggx_tables(roughness: tuple[float, ...], sizes: tuple[int, ...], samples: int, base: int, lod_bias: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs of probe_ggx.comp: samples (S, 4) = (local light dir, N.L / sum N.L), lods (S,), and per roughness
    level (face size, first output texel, first sample, sample count) (L, 4), all levels concatenated."""
    samp, lods, levels = [], [], []
    texel = first = 0
    for r, m in zip(roughness, sizes):
        if r <= 0.0:  # a mirror, as ggx_prefilter_level: the radiance at the mip whose texels match the output's
            local, w, lod = np.array([[0.0, 0.0, 1.0]]), np.ones(1), np.array([max(0.0, math.log2(base / m))])
        else:
            local, w, lod = ggx_samples(r, samples, base, lod_bias)
        samp.append(np.concatenate([local, (w / w.sum())[:, None]], 1))
        lods.append(lod)
        levels.append((m, texel, first, len(w)))
        texel += 6 * m * m
        first += len(w)
    return np.concatenate(samp), np.concatenate(lods), np.array(levels, np.uint32)


def gpu_ggx_prefilter(cube, roughness: tuple[float, ...] = DEFAULT_ROUGHNESS, sizes: tuple[int, ...] | None = None,
                      samples: int = 256, lod_bias: float = 1.0, ctx=None
                      ) -> tuple[list[np.ndarray], dict[str, float]]:
    """GGX prefiltered radiance on the GPU, one (6, size, size, 3) cube per roughness (see ggx.ggx_prefilter:
    same samples, mip lods and default sizes); every level in one dispatch."""
    n = cube.size if isinstance(cube, GpuCube) else np.shape(cube)[1]
    roughness = tuple(float(r) for r in roughness)
    if sizes is None:
        sizes = tuple(max(4, n >> k) for k in range(len(roughness)))
    if len(sizes) != len(roughness):
        raise ValueError(f"GGX prefilter: {len(roughness)} roughness levels but {len(sizes)} sizes")
    if not roughness:
        return [], {}
    if samples < 1 or min(sizes) < 1:
        raise ValueError(f"GGX prefilter: needs samples >= 1 and face sizes >= 1, got {samples} and {sizes}")
    samp, lods, levels = ggx_tables(roughness, tuple(int(m) for m in sizes), samples, n, lod_bias)
    ctx, src, n, owned = _source(cube, ctx)
    keep: list[Buffer] = [src] if owned else []
    total = int(sum(6 * m * m for m in sizes))
    sb, lb = _upload(ctx, samp, "probe-ggx-samples"), _upload(ctx, lods, "probe-ggx-lods")
    vb = Buffer(ctx, levels.nbytes, "probe-ggx-levels")
    vb.write(levels)
    out = Buffer(ctx, total * 3 * 4, "probe-ggx")
    keep += [sb, lb, vb, out]
    with Recorder(ctx, timestamps=True) as rec:
        chain, n_mips = _mip_chain(ctx, rec, src, n, keep)
        rec.timestamp("mips")
        rec.dispatch(ctx.pipeline("probe_ggx", 5, 16), [chain, sb, lb, vb, out], groups(total, 1, ctx),
                     pack("IIII", n, n_mips, len(sizes), total))
        rec.timestamp("ggx")
    flat = out.read(np.float32, total * 3).reshape(total, 3).astype(np.float64)
    for b in keep:
        b.destroy()
    cubes = [flat[first:first + 6 * m * m].reshape(6, m, m, 3) for m, first in levels[:, :2].astype(np.int64)]
    return cubes, rec.timings_ms
