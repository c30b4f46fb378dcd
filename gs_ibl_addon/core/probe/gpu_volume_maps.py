"""The light volume's maps made on the GPU from a render_probes frame with depth, so that a bake reads back each
probe's two small maps (P x 1447 floats) instead of its cube and depth (P x 6 f^2 x 5 floats) and does no numpy
matmul: volume_bake.maps_from_cubes is the plain numpy reference, tests/test_gpu_volume_maps.py compares the two.
The caller (volume_bake.bake_probes) passes the two matrices, so this stage imports nothing of the bake's.

Two kernels queued behind the render (render(wait=False): one submission and one wait for both; made again in the
rare case the render had to draw again, as filter_probes does): volume_maps_prep (holes filled, the irradiance's
box-average to IRR_FACE, the radial distances and their squares, each texel's hole and closeness weight) and
volume_maps_apply twice (the same fixed matrices as the numpy path, transposed, with one more row that sums the hole
or closeness weight: the hole fraction and the inside test come out with the maps). On a CPU device (lavapipe)
numpy's BLAS is ~20-40x faster than these kernels and the readback a memcpy: bake_probes keeps the host path there
(volume_bake.GPU_MAPS).
"""
from __future__ import annotations

import math

import numpy as np

from ..vk import Buffer, Recorder, groups, kept, scratch
from ..vk.kernels import KERNELS
from .gpu_filters import omega_table
from .volume import COVERED, IRR, VIS

PROBES_PER_GROUP = 4  # volume_maps_apply.comp's PROBES
# per probe, in the read-back buffer: irradiance (IRR^2 x 3), hole fraction, moments (VIS^2 x 2), closeness fraction
IRR_AT, VIS_AT = 0, IRR * IRR * 3 + 1
STRIDE = VIS_AT + VIS * VIS * 2 + 1


def _matrix(ctx, kind: str, m: np.ndarray) -> Buffer:
    """(n_in, rows + 1) float32 on the GPU: the map's (rows, n_in) matrix transposed, and a last column 1 / 4 pi
    (the weights' sum over the sphere: the hole or closeness fraction). Kept per context with the array it was
    made of (the bake's matrices are cached arrays: the same object each chunk), uploaded again for another."""
    key = ("volume-maps-" + kind, m.shape)
    b = ctx.cache.get(key)
    if b is not None and b.alive and b.source is m:
        return b
    if b is not None and b.alive:
        b.destroy()
    a = np.ascontiguousarray(np.concatenate([m, np.full((1, m.shape[1]), 1.0 / (4.0 * math.pi))]).T, np.float32)
    b = ctx.cache[key] = Buffer(ctx, a.nbytes, f"table-{key[0]}")
    b.write(a)
    b.source = m  # the context's cache closes the buffer; this keeps the array it was made of alive for `is`
    return b


def _face_of(m: np.ndarray, rows: int, what: str) -> int:
    g = int(round(math.sqrt(m.shape[1] / 6)))
    if m.shape != (rows, 6 * g * g):
        raise ValueError(f"the {what} matrix must be ({rows}, 6 face^2), not {m.shape}")
    return g


def volume_maps(frame, irradiance: np.ndarray, visibility: np.ndarray, far: float, near: float,
                hole_colour=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A render_probes frame with depth (P probes of f^2 faces) and the maps' matrices (volume_bake's
    irradiance_matrix(g), g^2 the frame's faces box-averaged (f a multiple of g), and visibility_matrix(f)) ->
    (irradiance (P, IRR, IRR, 3), moments (P, VIS, VIS, 2), hole fraction (P,), closeness fraction (P,): the share
    of the sphere covered by splats nearer than ``near``), float32, as maps_from_cubes and bake_probes' inside test
    give them."""
    f = frame.cube_face_size
    g = _face_of(irradiance, IRR * IRR, "irradiance")
    if _face_of(visibility, VIS * VIS, "visibility") != f or f % g:
        raise ValueError(f"matrices for faces {g}^2 and {_face_of(visibility, VIS * VIS, 'visibility')}^2 do not "
                         f"fit a frame of {f}^2 faces")
    if frame.depth is None:
        raise ValueError("the frame has no depth: render(batch, depth=True) writes it")
    frame.check()
    ctx, probes = frame.ctx, frame.probes
    n_irr, n_vis = 6 * g * g, 6 * f * f
    irr_in = scratch(ctx, probes * n_irr * 16, "volume-irr-in")
    vis_in = scratch(ctx, probes * n_vis * 16, "volume-vis-in")
    nbytes = probes * STRIDE * 4
    out = scratch(ctx, nbytes, "volume-maps")
    direct = out.host_visible and out.host_cached
    read = out if direct else kept(ctx, "volume-maps-read", nbytes, staging=True)
    hr, hg, hb = (float(c) for c in hole_colour)
    prog = None
    try:
        rec = Recorder(ctx, reusable=True)
        rec.dispatch(KERNELS["volume_maps_prep"], [frame.image, frame.depth, omega_table(ctx, f), irr_in, vis_in],
                     groups(probes * n_irr, 64, ctx), n=probes * n_irr, f=f, g=g, far=float(far),
                     near=float(near), covered=COVERED, hole_r=hr, hole_g=hg, hole_b=hb)
        wg = (-(-(IRR * IRR + 1) // 64), -(-probes // PROBES_PER_GROUP))
        rec.dispatch(KERNELS["volume_maps_apply"], [_matrix(ctx, "irr", irradiance), irr_in, out], wg, n_in=n_irr,
                     rows=IRR * IRR + 1, probes=probes, channels=3, stride=STRIDE, at=IRR_AT, extra=3)
        rec.dispatch(KERNELS["volume_maps_apply"], [_matrix(ctx, "vis", visibility), vis_in, out], wg, n_in=n_vis,
                     rows=VIS * VIS + 1, probes=probes, channels=2, stride=STRIDE, at=VIS_AT, extra=2)
        if not direct:
            rec.copy(out, read, nbytes)
        prog = rec.program()
        # queued behind a render still in flight (render(wait=False)): the host waits once for both, and makes the
        # maps again in the rare case the render had to be drawn again after they were queued
        prog.start()
        if frame.wait():
            prog.wait()
            prog.start()
        prog.wait()
        flat = read.read(np.float32, probes * STRIDE).reshape(probes, STRIDE)
    finally:
        if prog is not None:
            prog.close()
        for b in (irr_in, vis_in, out):
            b.close()
    irr = flat[:, :IRR * IRR * 3].reshape(probes, IRR, IRR, 3)
    mom = flat[:, VIS_AT:VIS_AT + VIS * VIS * 2].reshape(probes, VIS, VIS, 2)
    return irr, mom, flat[:, VIS_AT - 1].copy(), flat[:, STRIDE - 1].copy()
