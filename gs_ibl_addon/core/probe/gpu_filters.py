"""GPU (Vulkan compute) versions of the probe filters; each mirrors a numpy reference in this package.

  gpu_sh_project        -> sh_project.project_cube (order 2)     shaders/probe_sh_project.comp
  gpu_sh_irradiance     -> sh_project.sh_irradiance (order 2)    shaders/probe_sh_irradiance.comp
  gpu_cosine_convolve   -> convolve.cosine_convolve              shaders/probe_convolve.comp
  gpu_box_irradiance    -> box.box_irradiance                    shaders/probe_downsample.comp + probe_cube_read.comp
  gpu_exact_irradiance  -> reference.exact_irradiance of          shaders/probe_downsample.comp + probe_integrate.comp
                           box.downsample_cube^k (downsample_to)
  gpu_ggx_prefilter     -> ggx.ggx_prefilter                      shaders/probe_downsample.comp + probe_ggx.comp
  gpu_cube_to_latlong   -> latlong.cube_to_latlong                shaders/probe_latlong.comp

Cubes travel as packed float32 RGB (alpha is split off first: holes are black, as in numpy). Every filter takes
a numpy cube, a GpuCube (``upload_cube``: several filters of one cube then share one upload) or a GpuFrame straight
from the renderer (core.render.renderer): a frame's RGBA is split into the RGB cube on the GPU (probe_split_alpha),
so nothing crosses to the host but the filter's result. The SH reduction runs per workgroup on the GPU; the last
few dozen group partials are added on the host in float64. Solid angles come from core.cubemap (float64, uploaded
as float32 once per context and size), never recomputed in GLSL; likewise the GGX sample table (directions,
weights, mip lods) comes from ggx.ggx_samples, so both paths share one sequence. Scratch buffers come from the
context's pool. Each function returns (result, timings_ms) with GPU timestamps per stage where the device has them.

``FilterPlan`` is what filter_probe uses: [split] -> SH projection -> irradiance, recorded once per source and
settings and submitted again for each probe; it reads back the SH partials, the hole partials and the small
irradiance cube only.

Many probes (a frame of SplatRenderer.render_probes): ``filter_probes`` runs the same plan over all P cubes of
the frame at once, workgroup z being the probe in split, SH projection, downsampling and the exact integral (the
shaders offset their cube by z; z = 0 is the single probe), so P probes cost one submission and one read-back.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .. import cubemap
from ..vk import Buffer, Recorder, get_context
from ..vk import Program, groups, scratch
from ..vk.kernels import KERNELS
from .box import box_level_size, halving_sizes
from .convolve import check_steps, source_sizes
from .ggx import DEFAULT_ROUGHNESS, ggx_samples, level_sizes
from .reference import integration_size
from .sampling import split_alpha
from .sh_project import cosine_lobe_coefficients, window_factors

BATCH_METHODS = ("exact", "sh")  # irradiance methods filter_probes runs over many probes at once
SH_GROUPS_MAX = 64  # workgroups of the SH and hole reductions: enough to fill a GPU, few enough to sum on the host
PLANS_KEPT = 16  # recorded filter plans per context


def _rgb32(cube: np.ndarray) -> np.ndarray:
    rgb, _ = split_alpha(cube)
    if rgb.shape[3] != 3:
        raise ValueError(f"GPU probe filters take RGB(A) cubes, got {rgb.shape[3]} channels")
    return np.ascontiguousarray(rgb, np.float32)


def _is_frame(obj) -> bool:
    return hasattr(obj, "image") and hasattr(obj, "batch")  # render.renderer.GpuFrame (not imported: no cycle)


def _table(ctx, key: tuple, make) -> Buffer:
    """A constant table (solid angles, texel directions) uploaded once per context and kept in ctx.cache."""
    b = ctx.cache.get(key)
    if b is None or not b.alive:
        a = np.ascontiguousarray(make(), np.float32)
        b = ctx.cache[key] = Buffer(ctx, a.nbytes, f"table-{key[0]}")
        b.write(a)
    return b


def omega_table(ctx, n: int) -> Buffer:
    return _table(ctx, ("omega", n), lambda: cubemap.texel_solid_angles(n))


def texel_table(ctx, k: int) -> Buffer:
    """(direction, dOmega / pi) per texel of a k^2 cube: probe_integrate's input."""
    return _table(ctx, ("texels", k), lambda: np.concatenate(
        [cubemap.face_directions(k).reshape(-1, 3),
         np.tile(cubemap.texel_solid_angles(k).reshape(-1) / math.pi, 6)[:, None]], 1))


def _reduction_groups(n: int) -> int:
    return max(1, min(SH_GROUPS_MAX, -(-6 * n * n // 256)))


class _Scratch:
    """The buffers one filter call uses, taken from the context's pool: ``with _Scratch(ctx) as s:`` returns them
    all when the block ends, however it ends (a failed recording is never submitted, so nothing on the GPU still
    uses them)."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.buffers: list[Buffer] = []

    def __enter__(self) -> "_Scratch":
        return self

    def __exit__(self, *exc) -> None:
        while self.buffers:
            self.buffers.pop().close()

    def empty(self, nbytes: int, name: str) -> Buffer:
        b = scratch(self.ctx, nbytes, name)
        self.buffers.append(b)
        return b

    def upload(self, data: np.ndarray, name: str, dtype=np.float32) -> Buffer:
        a = np.ascontiguousarray(data, dtype)
        b = self.empty(a.nbytes, name)
        b.write(a)
        return b

    def source(self, rec: Recorder, cube) -> tuple[Buffer, int]:
        """(RGB buffer, face size) of a numpy cube (uploaded), a GpuCube (the caller's) or a GpuFrame (split on the
        GPU into a scratch buffer, recorded into ``rec``)."""
        if isinstance(cube, GpuCube):
            return cube.buffer, cube.size
        if _is_frame(cube):
            cube.wait()
            n = cube.face_size
            rgb = self.empty(6 * n * n * 12, "probe-radiance")
            hole = self.empty(SH_GROUPS_MAX * 4, "probe-hole-partial")
            record_split(rec, cube.image, rgb, hole, n)
            return rgb, n
        rgb = _rgb32(cube)
        return self.upload(rgb, "probe-radiance"), int(rgb.shape[1])


def record_split(rec: Recorder, frame_image: Buffer, rgb: Buffer, hole_partial: Buffer, n: int,
                 probes: int = 1) -> None:
    """Record frame RGBA -> packed RGB cube(s), and the hole partials (sum them, / 4pi: the hole fraction), for
    ``probes`` cubes one after another (partials: _reduction_groups(n) per probe)."""
    ctx = rec.ctx
    g = _reduction_groups(n)
    rec.dispatch(KERNELS["probe_split_alpha"], [frame_image, omega_table(ctx, n), rgb, hole_partial], (g, 1, probes),
                 n=n, n_groups=g)
    rec.timestamp("split")


class GpuCube:
    """A radiance cube on the GPU (packed float32 RGB, holes black); pass it to any filter here instead of the numpy
    cube to skip the per-call upload. Made from a numpy cube (uploaded once) or a GpuFrame (split on the GPU, no
    host transfer; ``hole_fraction`` then read back from the few partials). ``close()`` (or ``with``) frees it."""

    def __init__(self, cube, ctx=None) -> None:
        self.hole_fraction = 0.0
        if _is_frame(cube):
            cube.wait()
            self.ctx = cube.ctx
            self.size = n = cube.face_size
            self.buffer = Buffer(self.ctx, 6 * n * n * 12, "probe-radiance")
            with scratch(self.ctx, SH_GROUPS_MAX * 4, "probe-hole-partial") as hole:
                with Recorder(self.ctx) as rec:
                    record_split(rec, cube.image, self.buffer, hole, n)
                self.hole_fraction = hole_fraction(hole, n)
            return
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

    def __enter__(self) -> "GpuCube":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def hole_fraction(partial: Buffer, n: int) -> float:
    return float(partial.read(np.float32, _reduction_groups(n)).astype(np.float64).sum() / (4.0 * np.pi))


def upload_cube(cube, ctx=None) -> GpuCube:
    return GpuCube(cube, ctx)


def _context(cube, ctx):
    if isinstance(cube, GpuCube) or _is_frame(cube):
        return cube.ctx
    return ctx or get_context()


def _face_size(cube) -> int:
    if isinstance(cube, GpuCube):
        return cube.size
    if _is_frame(cube):
        return cube.face_size
    return int(np.shape(cube)[1])


def _downsample(rec: Recorder, scratch: _Scratch, sizes: list[int], src: Buffer, probes: int = 1) -> list[Buffer]:
    """Record 2x2 solid-angle downsampling (box.downsample_cube) along ``sizes`` (box.halving_sizes, starting at
    src's face size): one buffer per size, src first, each later one made from the one before (``probes`` cubes
    each)."""
    ctx = scratch.ctx
    levels = [src]
    for child, parent in zip(sizes, sizes[1:]):
        dst = scratch.empty(probes * 6 * parent * parent * 3 * 4, f"probe-mip-{parent}")
        rec.dispatch(KERNELS["probe_downsample"], [levels[-1], omega_table(ctx, child), dst],
                     groups(6 * parent * parent, 64, ctx) + (probes,), n=child)
        levels.append(dst)
    return levels


def _read_cube(buf: Buffer, size: int) -> np.ndarray:
    return buf.read(np.float32, 6 * size * size * 3).reshape(6, size, size, 3).astype(np.float64)


def _sh_partials(partial: Buffer, n_groups: int) -> np.ndarray:
    return partial.read(np.float32, n_groups * 27).reshape(n_groups, 9, 3).astype(np.float64).sum(axis=0)


def _record_sh_project(rec: Recorder, src: Buffer, n: int, part: Buffer, probes: int = 1) -> int:
    """Record the SH partials of ``probes`` cubes (27 floats per group, _reduction_groups(n) groups per probe)."""
    g = _reduction_groups(n)
    rec.dispatch(KERNELS["probe_sh_project"], [src, omega_table(rec.ctx, n), part], (g, 1, probes), n=n, n_groups=g)
    return g


def gpu_sh_project(cube, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Order-2 SH coefficients (9, 3) of a radiance cube (numpy, GpuCube or GpuFrame) on the GPU."""
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        part = scratch.empty(SH_GROUPS_MAX * 27 * 4, "probe-sh-partial")
        with Recorder(ctx, timestamps=True) as rec:
            src, n = scratch.source(rec, cube)
            n_groups = _record_sh_project(rec, src, n, part)
            rec.timestamp("sh_project")
        coeffs = _sh_partials(part, n_groups)
    return coeffs, rec.timings_ms


def _sh_scaled(coeffs: np.ndarray, window: str, window_width: float | None) -> np.ndarray:
    if coeffs.shape != (9, 3):
        raise ValueError(f"GPU SH irradiance takes order-2 RGB coefficients (9, 3), got {coeffs.shape}")
    band = cosine_lobe_coefficients(2) / math.pi * window_factors(2, window, window_width)
    return coeffs * np.repeat(band, [1, 3, 5])[:, None]


def gpu_sh_irradiance(coeffs: np.ndarray, size: int, window: str = "none", window_width: float | None = None,
                      clamp: bool = True, ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Irradiance cube (6, size, size, 3) of E/pi from order-2 radiance SH (9, 3), evaluated on the GPU."""
    ctx = ctx or get_context()
    scaled = _sh_scaled(coeffs, window, window_width)
    with _Scratch(ctx) as scratch:
        cb = scratch.upload(scaled, "probe-sh")
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            rec.dispatch(KERNELS["probe_sh_irradiance"], [cb, out], groups(6 * size * size, 64, ctx),
                         m=size, clamp_negative=int(clamp))
            rec.timestamp("sh_irradiance")
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def _record_convolve(rec: Recorder, scratch: _Scratch, src: Buffer, n: int, out: Buffer, size: int, phi_steps: int,
                     theta_steps: int) -> None:
    sizes = source_sizes(n, theta_steps)  # the grid reads a cube matched to its spacing
    src = _downsample(rec, scratch, sizes, src)[-1]
    rec.dispatch(KERNELS["probe_convolve"], [src, out], groups(6 * size * size, 64, rec.ctx),
                 n=sizes[-1], m=size, phi_steps=phi_steps, theta_steps=theta_steps)
    rec.timestamp("convolve")


def gpu_cosine_convolve(cube, size: int, phi_steps: int = 64, theta_steps: int = 16,
                        ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Cosine-convolved irradiance cube (6, size, size, 3) of E/pi on the GPU (see convolve.cosine_convolve)."""
    check_steps(phi_steps, theta_steps)
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            src, n = scratch.source(rec, cube)
            _record_convolve(rec, scratch, src, n, out, size, phi_steps, theta_steps)
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def _record_box(rec: Recorder, scratch: _Scratch, src: Buffer, n: int, out: Buffer, size: int, level: int) -> None:
    small = _downsample(rec, scratch, halving_sizes(n, level), src)[-1]
    rec.timestamp("downsample")
    rec.dispatch(KERNELS["probe_cube_read"], [small, out], groups(6 * size * size, 64, rec.ctx), n=level, m=size)
    rec.timestamp("read")


def gpu_box_irradiance(cube, size: int, level_size: int | None = None,
                       ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Thesis box filter on the GPU: 2x2 solid-angle downsampling to level_size, then a bilinear read by normal."""
    level = box_level_size(_face_size(cube), size, level_size)
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            src, n = scratch.source(rec, cube)
            _record_box(rec, scratch, src, n, out, size, level)
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def _record_exact(rec: Recorder, scratch: _Scratch, src: Buffer, n: int, out: Buffer, size: int, k: int,
                  probes: int = 1) -> None:
    small = _downsample(rec, scratch, halving_sizes(n, k), src, probes)[-1]
    rec.timestamp("downsample")
    rec.dispatch(KERNELS["probe_integrate"], [small, texel_table(rec.ctx, k), out],
                 groups(6 * size * size, 1, rec.ctx) + (probes,), n=k, m=size)
    rec.timestamp("integrate")


def gpu_exact_irradiance(cube, size: int, downsample_to: int | None = 32,
                         ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """Exact irradiance cube (6, size, size, 3) of E/pi on the GPU: the cube is box-downsampled (solid-angle
    weighted, power-preserving) to downsample_to per face, then every texel is integrated for every output
    normal. numpy reference: reference.exact_irradiance(box.downsample_cube^k(cube), face_directions(size))."""
    k = integration_size(_face_size(cube), downsample_to)
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        out = scratch.empty(6 * size * size * 3 * 4, "probe-irradiance")
        with Recorder(ctx, timestamps=True) as rec:
            src, n = scratch.source(rec, cube)
            _record_exact(rec, scratch, src, n, out, size, k)
        irr = _read_cube(out, size)
    return irr, rec.timings_ms


def gpu_cube_to_latlong(cube, width: int, height: int | None = None,
                        ctx=None) -> tuple[np.ndarray, dict[str, float]]:
    """(height, width, 3) lat-long image of a radiance cube (numpy, GpuCube or GpuFrame) on the GPU; numpy
    reference: latlong.cube_to_latlong (same seamless bilinear lookup, same mapping)."""
    if width < 2:
        raise ValueError(f"lat-long width must be >= 2, got {width}")
    height = max(1, width // 2) if height is None else int(height)
    ctx = _context(cube, ctx)
    with _Scratch(ctx) as scratch:
        out = scratch.empty(width * height * 12, "probe-latlong")
        with Recorder(ctx, timestamps=True) as rec:
            src, n = scratch.source(rec, cube)
            rec.dispatch(KERNELS["probe_latlong"], [src, out], groups(width * height, 64, ctx),
                         n=n, width=width, height=height)
            rec.timestamp("latlong")
        img = out.read(np.float32, width * height * 3).reshape(height, width, 3).astype(np.float64)
    return img, rec.timings_ms


def _mip_chain(rec: Recorder, scratch: _Scratch, src: Buffer, n: int) -> tuple[Buffer, int]:
    """Record box.mip_chain into one buffer (level after level, packed RGB): (buffer, number of levels)."""
    sizes = halving_sizes(n)
    chain = scratch.empty(sum(6 * s * s * 3 * 4 for s in sizes), "probe-mip-chain")
    rec.copy(src, chain, 6 * n * n * 3 * 4)
    offset = 6 * n * n * 3 * 4
    for size, mip in zip(sizes[1:], _downsample(rec, scratch, sizes, src)[1:]):
        nbytes = 6 * size * size * 3 * 4  # pooled buffers may be larger than the level
        rec.copy(mip, chain, nbytes, 0, offset)
        offset += nbytes
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
        sb, lb = scratch.upload(samp, "probe-ggx-samples"), scratch.upload(lods, "probe-ggx-lods")
        vb = scratch.upload(levels, "probe-ggx-levels", np.uint32)
        out = scratch.empty(total * 3 * 4, "probe-ggx")
        with Recorder(ctx, timestamps=True) as rec:
            src, n = scratch.source(rec, cube)
            chain, n_mips = _mip_chain(rec, scratch, src, n)
            rec.timestamp("mips")
            rec.dispatch(KERNELS["probe_ggx"], [chain, sb, lb, vb, out], groups(total, 1, ctx),
                         n=n, n_mips=n_mips, n_levels=len(sizes), total=total)
            rec.timestamp("ggx")
        flat = out.read(np.float32, total * 3).reshape(total, 3).astype(np.float64)
    cubes = [flat[first:first + 6 * m * m].reshape(6, m, m, 3) for m, first in levels[:, :2].astype(np.int64)]
    return cubes, rec.timings_ms


class FilterPlan:
    """filter_probe's GPU stages as one recorded program: [split a frame] -> SH order-2 projection -> irradiance
    (sh: evaluated afterwards from the coefficients; convolve, box, exact: in the same program). ``run()`` submits
    it and reads back only the SH and hole partials and the irradiance cube (6 * size^2 RGB).

    Made and cached per context by ``plan_for``: the source buffer (a renderer's frame image, or a pooled upload)
    and the settings are the key, so a bake's probes and a benchmark's repeats record once.
    """

    def __init__(self, ctx, src: Buffer, is_frame: bool, n: int, method: str, size: int, params: dict,
                 probes: int = 1) -> None:
        if probes > 1 and method not in BATCH_METHODS:
            raise ValueError(f"irradiance method {method!r} filters one probe at a time; several probes at once "
                             f"take {' or '.join(BATCH_METHODS)}")
        self.ctx, self.n, self.size, self.method, self.params = ctx, n, size, method, params
        self.is_frame, self.probes = is_frame, probes
        self._scratch = _Scratch(ctx)
        s = self._scratch
        g = _reduction_groups(n)
        self.sh_partial = s.empty(probes * g * 27 * 4, "probe-sh-partial")
        self.hole_partial = s.empty(probes * g * 4, "probe-hole-partial") if is_frame else None
        self.out = s.empty(probes * 6 * size * size * 12, "probe-irradiance") if method != "sh" else None
        rec = Recorder(ctx, timestamps=True, reusable=True)
        if is_frame:
            rgb = s.empty(probes * 6 * n * n * 12, "probe-radiance")
            record_split(rec, src, rgb, self.hole_partial, n, probes)
        else:
            rgb = src
        self.sh_groups = _record_sh_project(rec, rgb, n, self.sh_partial, probes)
        rec.timestamp("sh_project")
        if method == "convolve":
            check_steps(params["phi_steps"], params["theta_steps"])
            _record_convolve(rec, s, rgb, n, self.out, size, params["phi_steps"], params["theta_steps"])
        elif method == "box":
            _record_box(rec, s, rgb, n, self.out, size, box_level_size(n, size, params["box_level_size"]))
        elif method == "exact":
            _record_exact(rec, s, rgb, n, self.out, size, integration_size(n, params["downsample_to"]), probes)
        # The results end in one host-readable buffer, copied there by the program itself: reading them back is a
        # memcpy from mapped memory, not one more submission per result (on a discrete GPU a read of device
        # memory goes through a staging copy).
        parts = [(self.sh_partial, probes * g * 27 * 4), (self.hole_partial, probes * g * 4),
                 (self.out, probes * 6 * size * size * 12)]
        self.offsets, total = [], 0
        for buf, nbytes in parts:
            self.offsets.append(total)
            if buf is not None:
                rec.copy(buf, self._results(ctx, parts), nbytes, 0, total)
            total += nbytes
        self.program: Program = rec.program()

    def _results(self, ctx, parts) -> Buffer:
        if getattr(self, "results", None) is None:
            self.results = Buffer.staging(ctx, sum(nbytes for _, nbytes in parts), cached=True)
        return self.results

    @property
    def valid(self) -> bool:
        return self.program.valid

    def run(self) -> tuple[np.ndarray, np.ndarray | None, float, dict[str, float]]:
        """(SH coefficients (9, 3), irradiance cube or None for the sh method, hole fraction, GPU timings)."""
        self.program.start()
        return self.finish()

    def finish(self) -> tuple[np.ndarray, np.ndarray | None, float, dict[str, float]]:
        """Wait for the program (started by run() or program.start()) and read its results; one that is not
        running is run now. A plan of several probes: finish_all()."""
        coeffs, irr, hole, timings = self.finish_all()
        return coeffs[0], None if irr is None else irr[0], float(hole[0]), timings

    def finish_all(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, dict[str, float]]:
        """As finish(), with a leading probe axis: SH (P, 9, 3), irradiance (P, 6, m, m, 3) or None, holes (P,)."""
        if not self.program.running:
            self.program.start()
        timings = self.program.wait()
        res, (o_sh, o_hole, o_irr), p, g = self.results, self.offsets, self.probes, self.sh_groups
        coeffs = res.read(np.float32, p * g * 27, o_sh).reshape(p, g, 9, 3).astype(np.float64).sum(axis=1)
        hole = np.zeros(p)
        if self.hole_partial is not None:
            hole = res.read(np.float32, p * g, o_hole).reshape(p, g).astype(np.float64).sum(axis=1) / (4 * np.pi)
        irr = None
        if self.out is not None:
            m = self.size
            irr = res.read(np.float32, p * 6 * m * m * 3, o_irr).reshape(p, 6, m, m, 3).astype(np.float64)
        return coeffs, irr, hole, timings

    def close(self) -> None:
        self.program.close()
        self._scratch.__exit__(None, None, None)
        self.results.destroy()


def plan_for(ctx, src: Buffer, is_frame: bool, n: int, method: str, size: int, probes: int = 1,
             **params) -> FilterPlan:
    """The cached FilterPlan for this source buffer and these settings (recorded on first use or when stale)."""
    key = ("filter-plan", src.serial, is_frame, n, method, size, probes, tuple(sorted(params.items())))
    plan = ctx.cache.pop(key, None)
    if plan is not None and not plan.valid:
        plan.close()
        plan = None
    if plan is None:
        # Plans whose source is gone (a closed renderer's frame) give their pooled buffers back now; then the least
        # recently used go beyond PLANS_KEPT.
        for old in [k for k, v in ctx.cache.items() if k[0] == "filter-plan" and not v.valid]:
            ctx.cache.pop(old).close()
        plan = FilterPlan(ctx, src, is_frame, n, method, size, params, probes)
        plans = [k for k in ctx.cache if k[0] == "filter-plan"]
        for old in plans[:max(0, len(plans) - PLANS_KEPT + 1)]:
            ctx.cache.pop(old).close()
    ctx.cache[key] = plan
    return plan


@dataclass
class ProbesFiltered:
    """What filter_probes gives, one row per probe of the frame: order-2 radiance SH (P, 9, 3), irradiance E/pi
    (P, 6, size, size, 3), hole fractions (P,), and the GPU time of the whole filter (ms, per stage)."""
    sh_coefficients: np.ndarray
    irradiance: np.ndarray
    hole_fraction: np.ndarray
    timings_ms: dict[str, float]


def filter_probes(frame, irradiance_size: int = 16, method: str = "exact", downsample_to: int | None = 32,
                  sh_window: str = "none", ctx=None) -> ProbesFiltered:
    """Irradiance of every probe of a frame of SplatRenderer.render_probes (or of a numpy stack of cubes
    (P, 6, n, n, 3|4), uploaded once), in one submission over all 6P faces: split -> SH projection -> exact
    integral (method "exact", probe.reference.exact_irradiance of the cube box-downsampled to ``downsample_to``),
    or the order-2 SH evaluated per probe on the host (method "sh": 9 coefficients, nothing to batch). The
    render may still be in flight (render_probes(wait=False)): the filter is queued behind it and the host waits
    once for both. Each probe's result is what filter_probe gives for that probe's cube alone."""
    from .sh_project import sh_irradiance_faces
    if method not in BATCH_METHODS:
        raise ValueError(f"filter_probes takes method {' or '.join(BATCH_METHODS)}, not {method!r}")
    params = dict(phi_steps=64, theta_steps=16, box_level_size=1, downsample_to=downsample_to)
    upload = None
    if _is_frame(frame):
        frame.check()
        n, probes, ctx = frame.cube_face_size, frame.probes, frame.ctx
        plan = plan_for(ctx, frame.image, True, n, method, int(irradiance_size), probes, **params)
        plan.program.start()
        if frame.wait():  # the render was drawn again after this filter was queued: filter it again
            plan.program.wait()
    else:
        cubes = np.asarray(frame)
        if cubes.ndim != 5 or cubes.shape[1] != 6 or cubes.shape[2] != cubes.shape[3] or cubes.shape[4] not in (3, 4):
            raise ValueError(f"filter_probes takes a GpuFrame or cubes (P, 6, n, n, 3|4), got shape {cubes.shape}")
        rgb = np.ascontiguousarray(cubes[..., :3], np.float32)  # premultiplied: holes are black, as split_alpha
        probes, n, ctx = len(rgb), rgb.shape[2], ctx or get_context()
        upload = scratch(ctx, rgb.nbytes, "probe-radiance")
        upload.write(rgb)
        plan = plan_for(ctx, upload, False, n, method, int(irradiance_size), probes, **params)
        plan.program.start()
    try:
        coeffs, irr, holes, timings = plan.finish_all()
    finally:
        if upload is not None:
            upload.close()
    if irr is None:
        t0 = time.perf_counter()
        size = int(irradiance_size)
        # every probe's coefficients as channels of one call on the faces' SH basis (made once a session), not once
        # a probe (18 grid nodes: 2 ms of host time a filter on lavapipe's machine)
        p, k, c = coeffs.shape
        irr = np.moveaxis(sh_irradiance_faces(coeffs.transpose(1, 0, 2).reshape(k, p * c), size, sh_window)
                          .reshape((6, size, size, p, c)), -2, 0)
        timings = {**timings, "sh_irradiance_host": (time.perf_counter() - t0) * 1e3}
    return ProbesFiltered(coeffs, irr, holes, timings)
