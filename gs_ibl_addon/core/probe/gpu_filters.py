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
from .box import box_level_size, halving_sizes
from .convolve import check_steps
from .ggx import DEFAULT_ROUGHNESS, ggx_samples, level_sizes
from .reference import integration_size
from .sampling import split_alpha
from .sh_project import cosine_lobe_coefficients, window_factors

SH_GROUPS_MAX = 64  # workgroups of the SH reduction: enough to fill a GPU, few enough to sum on the host


def _rgb32(cube: np.ndarray) -> np.ndarray:
    rgb, _ = split_alpha(cube)
    if rgb.shape[3] != 3:
        raise ValueError(f"GPU probe filters take RGB(A) cubes, got {rgb.shape[3]} channels")
    return np.ascontiguousarray(rgb, np.float32)


class _Scratch:
    """The buffers one filter call allocates: ``with _Scratch(ctx) as s:`` destroys them all when the block ends,
    however it ends (a failed recording is never submitted, so nothing on the GPU still uses them)."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.buffers: list[Buffer] = []

    def __enter__(self) -> "_Scratch":
        return self

    def __exit__(self, *exc) -> None:
        while self.buffers:
            self.buffers.pop().destroy()

    def empty(self, nbytes: int, name: str) -> Buffer:
        b = Buffer(self.ctx, nbytes, name)
        self.buffers.append(b)
        return b

    def upload(self, data: np.ndarray, name: str, dtype=np.float32) -> Buffer:
        a = np.ascontiguousarray(data, dtype)
        b = self.empty(a.nbytes, name)
        b.write(a)
        return b

    def source(self, cube) -> tuple[Buffer, int]:
        """(buffer, face size) of a numpy cube (uploaded, owned here) or a GpuCube (the caller's)."""
        if isinstance(cube, GpuCube):
            return cube.buffer, cube.size
        rgb = _rgb32(cube)
        return self.upload(rgb, "probe-radiance"), int(rgb.shape[1])


class GpuCube:
    """A radiance cube uploaded once (packed float32 RGB, holes black); pass it to any filter here instead of
    the numpy cube to skip the per-call upload. ``close()`` frees it."""

    def __init__(self, cube: np.ndarray, ctx=None) -> None:
        self.ctx = ctx or get_context()
        rgb = _rgb32(cube)
        self.size = int(rgb.shape[1])
        self.buffer = Buffer(self.ctx, rgb.nbytes, "probe-radiance")
        try:
            self.buffer.write(rgb)
        except BaseException:
            self.buffer.destroy()
            raise

    def close(self) -> None:
        self.buffer.destroy()


def upload_cube(cube: np.ndarray, ctx=None) -> GpuCube:
    return GpuCube(cube, ctx)


def _context(cube, ctx):
    return cube.ctx if isinstance(cube, GpuCube) else (ctx or get_context())


def _face_size(cube) -> int:
    return cube.size if isinstance(cube, GpuCube) else int(np.shape(cube)[1])


def _downsample(rec: Recorder, scratch: _Scratch, sizes: list[int], src: Buffer) -> list[Buffer]:
    """Record 2x2 solid-angle downsampling (box.downsample_cube) along ``sizes`` (box.halving_sizes, starting at
    src's face size): one buffer per size, src first, each later one made from the one before."""
    ctx = scratch.ctx
    down = ctx.pipeline("probe_downsample", 3, 4)
    levels = [src]
    for child, parent in zip(sizes, sizes[1:]):
        omega = scratch.upload(cubemap.texel_solid_angles(child), f"probe-omega-{child}")
        dst = scratch.empty(6 * parent * parent * 3 * 4, f"probe-mip-{parent}")
        rec.dispatch(down, [levels[-1], omega, dst], groups(6 * parent * parent, 64, ctx), pack("I", child))
        levels.append(dst)
    return levels


def _read_cube(buf: Buffer, size: int) -> np.ndarray:
    return buf.read(np.float32, 6 * size * size * 3).reshape(6, size, size, 3).astype(np.float64)


def gpu_sh_project(cube, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Order-2 SH coefficients (9, 3) of a radiance cube (numpy or GpuCube) on the GPU."""
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        src, n = scratch.source(cube)
        n_groups = max(1, min(SH_GROUPS_MAX, -(-6 * n * n // 256)))
        omega = scratch.upload(cubemap.texel_solid_angles(n), "probe-omega")
        part = scratch.empty(n_groups * 27 * 4, "probe-sh-partial")
        with Recorder(ctx, timestamps=True) as rec:
            rec.dispatch(ctx.pipeline("probe_sh_project", 3, 8), [src, omega, part], n_groups,
                         pack("II", n, n_groups))
            rec.timestamp("sh_project")
        coeffs = part.read(np.float32, n_groups * 27).reshape(n_groups, 9, 3).astype(np.float64).sum(axis=0)
    return coeffs, rec.timings_ms


def gpu_sh_irradiance(coeffs: np.ndarray, size: int, window: str = "none", window_width: float | None = None,
                      clamp: bool = True, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Irradiance cube (6, size, size, 3) of E/pi from order-2 radiance SH (9, 3), evaluated on the GPU."""
    ctx = ctx or get_context()
    if coeffs.shape != (9, 3):
        raise ValueError(f"GPU SH irradiance takes order-2 RGB coefficients (9, 3), got {coeffs.shape}")
    band = cosine_lobe_coefficients(2) / math.pi * window_factors(2, window, window_width)
    scaled = coeffs * np.repeat(band, [1, 3, 5])[:, None]
    with _Scratch(ctx) as scratch:
        cb = scratch.upload(scaled, "probe-sh")
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            rec.dispatch(ctx.pipeline("probe_sh_irradiance", 2, 8), [cb, out], groups(6 * size * size, 64, ctx),
                         pack("II", size, int(clamp)))
            rec.timestamp("sh_irradiance")
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def gpu_cosine_convolve(cube, size: int, phi_steps: int = 64, theta_steps: int = 16,
                        ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Cosine-convolved irradiance cube (6, size, size, 3) of E/pi on the GPU (see convolve.cosine_convolve)."""
    check_steps(phi_steps, theta_steps)
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        src, n = scratch.source(cube)
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            rec.dispatch(ctx.pipeline("probe_convolve", 2, 16), [src, out], groups(6 * size * size, 64, ctx),
                         pack("IIII", n, size, phi_steps, theta_steps))
            rec.timestamp("convolve")
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def gpu_box_irradiance(cube, size: int, level_size: int | None = None,
                       ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Thesis box filter on the GPU: 2x2 solid-angle downsampling to level_size, then a bilinear read by normal."""
    level = box_level_size(_face_size(cube), size, level_size)
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        src, n = scratch.source(cube)
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            small = _downsample(rec, scratch, halving_sizes(n, level), src)[-1]
            rec.timestamp("downsample")
            rec.dispatch(ctx.pipeline("probe_cube_read", 2, 8), [small, out], groups(6 * size * size, 64, ctx),
                         pack("II", level, size))
            rec.timestamp("read")
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def gpu_exact_irradiance(cube, size: int, downsample_to: int | None = 32,
                         ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Exact irradiance cube (6, size, size, 3) of E/pi on the GPU: the cube is box-downsampled (solid-angle
    weighted, power-preserving) to downsample_to per face, then every texel is integrated for every output
    normal. numpy reference: reference.exact_irradiance(box.downsample_cube^k(cube), face_directions(size))."""
    k = integration_size(_face_size(cube), downsample_to)
    ctx = _context(cube, ctx)
    texels = np.concatenate([cubemap.face_directions(k).reshape(-1, 3),
                             np.tile(cubemap.texel_solid_angles(k).reshape(-1) / math.pi, 6)[:, None]], 1)
    with _Scratch(ctx) as scratch:
        src, n = scratch.source(cube)
        tex = scratch.upload(texels, "probe-texels")
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            small = _downsample(rec, scratch, halving_sizes(n, k), src)[-1]
            rec.timestamp("downsample")
            rec.dispatch(ctx.pipeline("probe_integrate", 3, 8), [small, tex, out], groups(6 * size * size, 1, ctx),
                         pack("II", k, size))
            rec.timestamp("integrate")
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def _mip_chain(rec: Recorder, scratch: _Scratch, src: Buffer, n: int) -> tuple[Buffer, int]:
    """Record box.mip_chain into one buffer (level after level, packed RGB): (buffer, number of levels)."""
    sizes = halving_sizes(n)
    chain = scratch.empty(sum(6 * s * s * 3 * 4 for s in sizes), "probe-mip-chain")
    rec.copy(src, chain, 6 * n * n * 3 * 4)
    offset = 6 * n * n * 3 * 4
    for mip in _downsample(rec, scratch, sizes, src)[1:]:
        rec.copy(mip, chain, mip.nbytes, 0, offset)
        offset += mip.nbytes
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
    n = _face_size(cube)
    roughness = tuple(float(r) for r in roughness)
    sizes = level_sizes(n, roughness, sizes, samples)
    if not roughness:
        return [], {}
    samp, lods, levels = ggx_tables(roughness, sizes, samples, n, lod_bias)
    ctx = _context(cube, ctx)
    total = int(sum(6 * m * m for m in sizes))
    with _Scratch(ctx) as scratch:
        src, n = scratch.source(cube)
        sb, lb = scratch.upload(samp, "probe-ggx-samples"), scratch.upload(lods, "probe-ggx-lods")
        vb = scratch.upload(levels, "probe-ggx-levels", np.uint32)
        out = scratch.empty(total * 3 * 4, "probe-ggx")
        with Recorder(ctx, timestamps=True) as rec:
            chain, n_mips = _mip_chain(rec, scratch, src, n)
            rec.timestamp("mips")
            rec.dispatch(ctx.pipeline("probe_ggx", 5, 16), [chain, sb, lb, vb, out], groups(total, 1, ctx),
                         pack("IIII", n, n_mips, len(sizes), total))
            rec.timestamp("ggx")
        flat = out.read(np.float32, total * 3).reshape(total, 3).astype(np.float64)
    cubes = [flat[first:first + 6 * m * m].reshape(6, m, m, 3) for m, first in levels[:, :2].astype(np.int64)]
    return cubes, rec.timings_ms
