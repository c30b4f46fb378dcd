"""Per-splat maths shared by the numpy reference renderer and mirrored line by line in shaders/gs_preprocess.comp.

Each Gaussian is evaluated along each pixel's ray, not through a projected 2D conic: the opacity a ray sees is
``opacity * exp(-m / 2)`` with m the smallest squared Mahalanobis distance of the ray to the splat centre. This is
a property of the ray alone, so a splat reads the same on both cube faces of an edge (no seams), and it is exact
at any field of view where the EWA local-affine approximation of 3DGS is not. It equals 3DGS at the image centre.

3DGS's anti-aliasing dilation (+0.3 px^2 on the 2D covariance) becomes an isotropic 3D variance of the same
screen size at the splat's distance: delta = sqrt(0.3) * dilation_angle * distance. For a view meant to look like
the trained scene the angle is the view's pixel and the opacity is left alone, as 3DGS does. For a probe, whose
images are integrated into light, the dilation has one size at every face size (PROBE_DILATION_ANGLE) and is energy
preserving: the footprint a ray sees is the covariance projected on the plane normal to the
viewing direction u (its determinant there is u^T adj(Sigma) u), the dilation adds delta^2 in that plane, and the
opacity is scaled by sqrt(det / det') so the footprint's integral stays put. A small bright splat seen by a coarse
probe face keeps its power instead of growing with the pixel size; a thin disk seen face-on is left alone.

Why one size for probes. Dilating by the face's own pixel keeps each splat's integral but not a cluster's: the
overlapping opaque splats of a lamp each grow and thin out, the ones behind show through, and the lamp as a whole
sent 2.3x its light at 32^2 and 1.5x at 64^2 (docs/accuracy.md). With the dilation of a 1024^2 face at every size,
a coarse face reads the same radiance at fewer points: the sample room's irradiance is 0.9% off at 32^2 and 0.1% at
64^2 (17.7% and 7.3% dilated by the face's pixel). What it gives up: splats far below a texel (a starfield) are hit
or missed, not averaged, and need finer faces; the face-size search sees it in the change between sizes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..colour import splat_radiance
from ..scene import SplatScene, quat_to_matrix
from ..sh import eval_sh_color
# shared with the GLSL
from ..vk.constants import (DEPTH_KEY_SHIFT, SORT_VIEW_DEPTH, STRIP_MAX_COND, STRIP_PAD_ABS, STRIP_PAD_REL, TIE_BITS,
                            TILE)

DILATION_PX2 = 0.3
PROBE_DILATION_ANGLE = 2.0 / 1024  # a 1024^2 cube face's pixel: the truth every probe face size converges to
ALPHA_MIN = 1.0 / 255.0  # 3DGS: a splat's footprint ends where its alpha falls below this
ALPHA_MAX = 0.99
T_MIN = 1e-4
DEFAULT_NEAR = 0.01


@dataclass
class PreparedSplats:
    whiten: np.ndarray  # (N, 3, 3): W = diag(1/s') R^T maps world offsets to the splat's unit frame
    origin_local: np.ndarray  # (N, 3): W (origin - mu)
    color: np.ndarray  # (N, 3) SH colour toward the splat from the origin
    opacity: np.ndarray  # (N,)
    cutoff: np.ndarray  # (N,) footprint: m <= 2 ln(255 * opacity of the file), kept when dimming for energy
    distance: np.ndarray  # (N,) from the origin; the sort key
    cov_cut: np.ndarray  # (N, 3, 3): cutoff * Sigma', the ellipsoid whose projection bounds the splat
    alive: np.ndarray  # (N,) bool: beyond the near distance, with a footprint


def prepare(scene: SplatScene, origin: np.ndarray, dilation_angle: float, near: float = DEFAULT_NEAR,
            energy_preserving: bool = False) -> PreparedSplats:
    mu = scene.positions.astype(np.float64) - np.asarray(origin, np.float64)
    dist = np.linalg.norm(mu, axis=1)
    rot = quat_to_matrix(scene.rotations)
    delta2 = DILATION_PX2 * (dilation_angle * dist) ** 2
    s2 = scene.scales.astype(np.float64) ** 2 + delta2[:, None]
    sp = np.sqrt(s2)
    whiten = np.transpose(rot, (0, 2, 1)) / sp[:, :, None]
    origin_local = -np.einsum("nij,nj->ni", whiten, mu)
    dirs = mu / np.maximum(dist, 1e-30)[:, None]
    color = splat_radiance(eval_sh_color(scene.sh, dirs), scene.colour_space)  # the colour rule (core/colour.py)
    op = scene.opacities.astype(np.float64)
    # The footprint stays 3DGS's (undimmed alpha >= 1/255): a splat dimmed for energy keeps its extent and its light
    cutoff = 2.0 * np.log(np.maximum(op / ALPHA_MIN, 1e-30))
    if energy_preserving:
        q = scene.scales.astype(np.float64) ** 2
        c = np.einsum("ni,nik->nk", mu / np.maximum(dist, 1e-30)[:, None], rot) ** 2  # (u . R_k)^2
        det = c[:, 0] * q[:, 1] * q[:, 2] + c[:, 1] * q[:, 0] * q[:, 2] + c[:, 2] * q[:, 0] * q[:, 1]
        tr = np.sum(q * (1 - c), 1)
        op = op * np.sqrt(det / np.maximum(det + delta2 * tr + delta2 ** 2, 1e-300))
    cov = np.einsum("nij,nj,nkj->nik", rot, s2, rot)
    alive = (dist > near) & (cutoff > 0)
    return PreparedSplats(whiten, origin_local, color, op, cutoff, dist, cov * np.maximum(cutoff, 0)[:, None, None],
                          alive)


def ray_mahalanobis(p: PreparedSplats, index: np.ndarray | slice,
                    dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For splats ``index`` and rays (P, 3): (m, t, in_front), each (S, P). m is the squared distance of the ray's
    line to the centre in the whitened frame, |o' x d'|^2 / |d'|^2; t = -o'.d' / |d'|^2 is where along the ray
    (in units of d) the closest approach lies, which must be ahead (t > 0)."""
    dl = np.einsum("sij,pj->spi", p.whiten[index], dirs)
    ol = p.origin_local[index][:, None, :]
    cr = np.cross(ol, dl)
    dd = np.sum(dl * dl, -1)
    od = np.sum(ol * dl, -1)
    return np.sum(cr * cr, -1) / dd, -od / dd, od < 0


@dataclass
class PlaneForm:
    """A splat's m along every ray of one view as exact forms in the view's image plane, as the GPU raster takes it
    (gs_raster.glsl plane_form). All (S,) float64 arrays."""
    s0: np.ndarray  # image-plane coordinates of the centre's ray (right, down; the view's tan units)
    t0: np.ndarray
    qss: np.ndarray  # q = qss ds^2 + 2 qst ds dt + qtt dt^2
    qst: np.ndarray
    qtt: np.ndarray
    ls: np.ndarray  # l = ls ds + lt dt
    lt: np.ndarray
    vss: np.ndarray  # v = vss ds^2 + 2 vst ds dt + vtt dt^2
    vst: np.ndarray
    vtt: np.ndarray
    z: np.ndarray  # the centre's depth along the view's forward axis
    held: np.ndarray  # bool: the GPU takes the form (else the ray test)


def plane_form(p: PreparedSplats, index: np.ndarray | slice, forward, right, down) -> PlaneForm:
    """The ray test's m of each splat, rewritten about its centre's ray in the view (forward, right, down).

    A pixel's ray is d = d0 + ds right + dt down with d0 = mu / z the ray through the centre (z = forward . mu;
    (s0, t0) its image coordinates). The whitened ray is then Wd = -o'/z + ds a + dt b (a = W right, b = W down,
    o' = -W mu), so with D0 = |o'|^2 / z^2 the ray test's m = |o' x Wd|^2 / |Wd|^2 is, exactly,
    m = q / (1 - l + v): q = |ds (o' x a) + dt (o' x b)|^2 / D0, l = 2 (ds a.o' + dt b.o') / (z D0) and
    v = |ds a + dt b|^2 / D0. The closest approach, -o'.Wd / |Wd|^2 along d, is z (1 - l/2) / (1 - l + v): ahead
    where l < 2. Each term is of the footprint's own size, so float keeps what the ray test's cross product of two
    near-parallel long vectors loses for small far splats. Held (the GPU takes it) for a splat well in front of the
    view (z > 0.2 |mu|) whose q is not too ill-conditioned to evaluate in float: tr(q)^2 <= 1e3 det(q)."""
    f, r, dn = (np.asarray(v, np.float64) for v in (forward, right, down))
    w = p.whiten[index]
    ol = p.origin_local[index]
    mu = -np.linalg.solve(w, ol[..., None])[..., 0]  # the GPU takes W's rows as orthogonal: the same to rounding
    z = mu @ f
    a, b = w @ r, w @ dn
    xa, xb = np.cross(ol, a), np.cross(ol, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        iz, id0 = 1 / z, z * z / np.sum(ol * ol, 1)
        qss, qtt, qst = np.sum(xa * xa, 1) * id0, np.sum(xb * xb, 1) * id0, np.sum(xa * xb, 1) * id0
        xab = np.cross(xa, xb)
        held = (z > 0.2 * np.linalg.norm(mu, axis=1)) & ((qss + qtt) ** 2 <= 1e3 * np.sum(xab * xab, 1) * id0 ** 2)
        return PlaneForm(mu @ r * iz, mu @ dn * iz, qss, qst, qtt, 2 * np.sum(a * ol, 1) * iz * id0,
                         2 * np.sum(b * ol, 1) * iz * id0, np.sum(a * a, 1) * id0, np.sum(a * b, 1) * id0,
                         np.sum(b * b, 1) * id0, z, held)


def plane_form_m(form: PlaneForm, s: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """As ray_mahalanobis, for image-plane points (P,) s, t: (m, t along the ray, ahead), each (S, P)."""
    c = {k: getattr(form, k)[:, None] for k in ("s0", "t0", "qss", "qst", "qtt", "ls", "lt", "vss", "vst", "vtt", "z")}
    ds, dt = s[None] - c["s0"], t[None] - c["t0"]
    q = ds * (c["qss"] * ds + 2 * c["qst"] * dt) + c["qtt"] * dt * dt
    lin = c["ls"] * ds + c["lt"] * dt
    den = 1 - lin + ds * (c["vss"] * ds + 2 * c["vst"] * dt) + c["vtt"] * dt * dt
    return q / den, c["z"] * (1 - 0.5 * lin) / den, lin < 2


STRIP_ROWS = 2  # pixel rows a strip of the strip raster (gs_raster.glsl RASTER_STRIPS): a warp of 32 on NVIDIA


def strip_bits(t0, A, B2, C, D, E, F, t_first: float, t_step: float, dtype: type = np.float64) -> np.ndarray:
    """The strips of STRIP_ROWS rows of a tile that footprints e(ds, dt) = A ds^2 + B2 ds dt + C dt^2 + D ds + E dt
    + F <= 0 about image points (., t0) may reach, as gs_raster.glsl strip_mask gives them: uint32 bits, strip i =
    rows 2i, 2i + 1 of the tile, whose first row's centre is at image coordinate ``t_first``, ``t_step`` apart.
    Arguments broadcast; ``dtype``: the arithmetic's (float32 is the GPU's).

    Where e's ds^2 coefficient and its minimum over ds are both convex in dt, the rows e reaches are the interval
    of dt where min over ds of e <= 0: the roots of a quadratic, mid +- h. Padded by STRIP_PAD_REL of (h + |mid| + a
    row) and STRIP_PAD_ABS of |t0| + 1, far past float32's rounding of e at a pixel; a footprint that is no
    ellipse, or one conditioned worse than STRIP_MAX_COND (a needle, whose bound cancels in float32), reaches every
    strip."""
    f = lambda x: np.asarray(x, dtype)  # noqa: E731
    A, B2, C, D, E, F, t0 = (f(x) for x in (A, B2, C, D, E, F, t0))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ia = f(0.25) / A
        a, b, cc = C - B2 * B2 * ia, E - B2 * D * (f(2) * ia), F - D * D * ia
        h = np.sqrt(np.maximum(b * b - f(4) * a * cc, f(0))) / (f(2) * a)
        mid = -b / (f(2) * a)
        tf, ts = f(t_first), f(t_step)
        pad = f(STRIP_PAD_REL) * (h + np.abs(mid) + ts) + f(STRIP_PAD_ABS) * (np.abs(t0) + f(1))
        lo = np.ceil((t0 + mid - h - pad - tf) / ts)
        hi = np.floor((t0 + mid + h + pad - tf) / ts)
        ellipse = (A > 0) & (a > 0) & ((A + C) * (A + C) <= f(STRIP_MAX_COND) * (A * a))
    rows = TILE - 1
    ellipse &= ~np.isnan(lo) & ~np.isnan(hi)
    reach = ellipse & (hi >= 0) & (lo <= rows) & (lo <= hi)
    s0 = np.where(reach, np.clip(lo, 0, rows), 0).astype(np.int64) // STRIP_ROWS
    s1 = np.where(reach, np.clip(hi, 0, rows), 0).astype(np.int64) // STRIP_ROWS
    bits = ((np.int64(2) << s1) - 1) & ~((np.int64(1) << s0) - 1)
    every = (1 << (TILE // STRIP_ROWS)) - 1
    return np.where(~ellipse, every, np.where(reach, bits, 0)).astype(np.uint32)


def strip_mask(form: PlaneForm, cut: np.ndarray, t_first: float, t_step: float,
               dtype: type = np.float64) -> np.ndarray:
    """strip_bits of each held plane form's footprint (the plain kernel's plane_strips): the footprint test m <= c
    is e = q - c (1 - l + v) <= 0 (1 - l + v = |Wd|^2 / D0 > 0), a quadratic in (ds, dt). (S,) uint32."""
    c = np.asarray(cut, np.float64)
    return strip_bits(form.t0, form.qss - c * form.vss, 2 * form.qst - c * 2 * form.vst, form.qtt - c * form.vtt,
                      c * form.ls, c * form.lt, -c, t_first, t_step, dtype)


def _pcg(v: np.ndarray) -> np.ndarray:
    """PCG hash of uint32s (Jarzynski & Olano 2020), as pcg() in shaders/gs_preprocess.comp."""
    state = v * np.uint32(747796405) + np.uint32(2891336453)
    word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


def tie_hash(positions: np.ndarray) -> np.ndarray:
    """(N,) uint32 hash of each splat's float32 position bits: the depth sort's tie rule."""
    b = np.ascontiguousarray(positions, np.float32).view(np.uint32).reshape(-1, 3)
    with np.errstate(over="ignore"):
        return _pcg(b[:, 0] ^ _pcg(b[:, 1] ^ _pcg(b[:, 2])))


def tie_bits(positions: np.ndarray) -> np.ndarray:
    """(N,) uint32: the TIE_BITS of tie_hash that order co-distant splats."""
    return tie_hash(positions) >> np.uint32(32 - TIE_BITS)


SORT_DEPTH_MIN = np.float32(1e-20)  # gs_preprocess.comp: a one-view batch's sort depth is at least this (> 0)


def sort_depths(scene: SplatScene, origin: np.ndarray, forward: np.ndarray | None = None) -> np.ndarray:
    """(N,) float32: what the depth sort orders by. ``forward`` None (probes: one order for all six faces): the
    distance from the origin; a view's (unit) forward (batches of one view: camera frames, the viewport): the depth
    along the view axis, z = forward . mu, as 3DGS sorts, clamped to SORT_DEPTH_MIN so that a splat centred behind
    the camera plane comes first (positive floats order as their bits)."""
    mu = scene.positions.astype(np.float32) - np.asarray(origin, np.float32)
    if forward is None:
        return np.sqrt(np.sum(mu * mu, axis=1, dtype=np.float32), dtype=np.float32)
    z = mu @ np.asarray(forward, np.float32).reshape(3)
    return np.maximum(z.astype(np.float32), SORT_DEPTH_MIN)


def batch_forward(batch) -> np.ndarray | None:
    """The forward that orders a ViewBatch's splats (sort_depths): its view's where the batch sorts by view depth
    (ViewBatch.sort: camera views), None where it sorts by distance (probe faces, even one face rendered alone: a
    probe's faces share one order) (gs_preprocess.comp sort_depth)."""
    return np.asarray(batch.views[0].forward, np.float64) if batch.sort == SORT_VIEW_DEPTH else None


def depth_keys(scene: SplatScene, origin: np.ndarray, forward: np.ndarray | None = None) -> np.ndarray:
    """The depth order's keys: float32 sort depth bits (sort_depths: distance from the origin, or with ``forward``
    depth along that view axis) without their low 8 bits, then TIE_BITS of tie_hash. Splats whose depths agree to
    3e-5 composite in an order set by their positions, whatever the file's order; only those whose hashes also agree
    keep storage order, on the GPU and here (stable argsort) alike. The GPU sorts the depth bits alone of splats
    uploaded in tie_order: the same order (constants.py)."""
    dist = sort_depths(scene, origin, forward)
    return ((dist.view(np.uint32) >> np.uint32(DEPTH_KEY_SHIFT)) << np.uint32(TIE_BITS)) | tie_bits(scene.positions)


def tie_order(positions: np.ndarray) -> np.ndarray:
    """(N,) indices: the splats ordered stably by their tie_bits (storage order within equal bits). The
    renderer uploads splats in this order, and its stable depth sort of the distance bits alone keeps it among
    co-distant splats: depth_keys' order without a pass for the tie bits."""
    return np.argsort(tie_bits(positions), kind="stable")
