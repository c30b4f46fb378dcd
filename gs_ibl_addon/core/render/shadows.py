"""Shadows of meshes on the capture, in numpy: how much of a probe's light each splat pixel of a final render loses
to the meshes standing in it (issue 36, item 3; docs/final-frame.md, "Shadows").

The capture's colours already hold its own shadows and its light; what it cannot hold is a mesh added to it. So a
splat pixel is multiplied by the share of its light that no mesh blocks:

    ratio = sum_k L_k max(0, n . l_k) V_k / sum_k L_k max(0, n . l_k)          (per RGB channel)

over light samples k (a direction l_k toward the light and its RGB weight L_k, irradiance at normal incidence),
n the capture's surface normal there and V_k whether the meshes leave the way to the light open. It is 1 where no
mesh is in the way, whatever the capture's colours or the light's strength, so the capture is never relit, only
shadowed. A mesh also reflects light into its own shadow: where it blocks sample k it gives back its own radiance,
albedo x E(-l_k) / pi over the sample's solid angle (``bounce``: its face toward the receiver lit by the probe,
diffuse, unshadowed), so a grey sphere's shadow is lighter than a black one's, as a path tracer has it.

The light samples (``light_samples``) come from the probe: its environment (the lat-long the World shows), split
into its bright compact part (a sun, a lamp, a window: texels over ``BRIGHT_FACTOR`` times the median, as the bake's
light finder has it, core/probe/lights.py) and the rest (sky, walls), each sampled by its own share of samples in
proportion to its power (a 2D low-discrepancy set through the texels' inverse CDF, so the samples spread over the
source: a sun's samples cover its disc and give its penumbra, the sky's give contact darkening); plus the lights a
bake split off the probe (Blender suns: direction, irradiance, angle), each a disc of samples of its width.

Visibility (``shadow_ratio``): one orthographic shadow map per sample (mesh_depth.rasterise_ortho: the meshes'
depth along the light, over their own footprint, so a receiver outside it is lit), looked up with a 2x2
percentage-closer filter. Only meshes are in the maps: the capture's own occluders are already in its colours.

The receivers (``surface_points``): each pixel's point on the capture from the renderer's depth (the coverage-
weighted depth of FRONT over BEHIND along the view axis), its normal from that depth's differences (the smaller
of the one-sided ones, so an edge does not bend it), at a reduced resolution where the frame is large, the ratio
brought back to full size by depth-aware (joint bilateral) upsampling.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..probe.lights import BRIGHT_FACTOR, LUMA, weighted_median
from .mesh_depth import rasterise_ortho

BRIGHT_SAMPLES = 32  # directions over the environment's bright compact part (penumbra steps)
SKY_SAMPLES = 96  # directions over the rest (contact darkening)
LIGHT_SAMPLES = 24  # directions over each disc of a split-off light
BRIGHT_MAP = 256  # shadow map side (texels) for the bright part's and the lights' samples
SKY_MAP = 128  # for the sky's: many soft overlapping shadows need less detail
TRIANGLE_BUDGET = 5e6  # casters' triangles x light samples per frame before the counts shrink (sample_scale)
MAX_SIDE = 480  # receivers are computed on a grid no larger than this (the frame's larger side, in samples)
MIN_ALPHA = 0.05  # pixels of less splat coverage are left as they are
SOFT_FROM = 4.0  # texels: a sample's shadow is spread over its patch once that is wider (visibility)
DEPTH_TOLERANCE = 0.03  # upsampling: a sample this much nearer or farther (relative) is on another surface


@dataclass(frozen=True)
class LightSamples:
    """Directions toward the light (K, 3) unit, their RGB weights (K, 3) (irradiance at normal incidence each
    carries), the side of their shadow maps (K,) and the solid angle each stands for (K,) (sr: what a mesh in
    front of it replaces)."""
    directions: np.ndarray
    weights: np.ndarray
    map_sides: np.ndarray
    solid_angles: np.ndarray

    @property
    def count(self) -> int:
        return len(self.directions)


def _radical_inverse(k: np.ndarray) -> np.ndarray:
    """Van der Corput in base 2 of each integer in ``k``."""
    k = np.asarray(k, np.uint64)
    out = np.zeros(k.shape, np.float64)
    f = 0.5
    while np.any(k):
        out += f * (k & np.uint64(1))
        k = k >> np.uint64(1)
        f *= 0.5
    return out


def _sample_texels(power: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, continuous columns) of ``n`` samples of a lat-long texel power map (H, W) in proportion to power:
    a Hammersley set through the rows' marginal and each row's conditional inverse CDF."""
    h, w = power.shape
    k = np.arange(n)
    u1, u2 = (k + 0.5) / n, _radical_inverse(k)
    rows_p = power.sum(1)
    row_cdf = np.cumsum(rows_p) / rows_p.sum()
    rows = np.minimum(np.searchsorted(row_cdf, u1, "right"), h - 1)
    cond = np.cumsum(power[rows], 1)
    cond /= np.maximum(cond[:, -1:], 1e-300)
    cols = np.array([min(np.searchsorted(c, v, "right"), w - 1) for c, v in zip(cond, u2)])
    # where within the texel: the part of u2 that falls inside it (keeps the samples spread inside a wide texel)
    lo = np.where(cols > 0, cond[np.arange(n), np.maximum(cols - 1, 0)], 0.0)
    hi = cond[np.arange(n), cols]
    frac = np.clip((u2 - lo) / np.maximum(hi - lo, 1e-300), 0.0, 1.0)
    return rows, cols + frac


def _latlong_direction(rows: np.ndarray, cols: np.ndarray, h: int, w: int) -> np.ndarray:
    """Directions at texel row ``rows`` (centre) and continuous column ``cols`` (cubemap.latlong_directions' map)."""
    theta = (rows + 0.5) / h * np.pi
    phi = (0.5 - cols / w) * 2.0 * np.pi
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], -1)


def environment_samples(latlong: np.ndarray, bright_samples: int = BRIGHT_SAMPLES,
                        sky_samples: int = SKY_SAMPLES) -> LightSamples:
    """Light samples of a lat-long environment (H, 2H, 3) linear RGB radiance (Blender's equirectangular map, top
    row +Z): its bright compact part and the rest, each sampled in proportion to its power. The weights sum to
    the environment's integral of radiance over the sphere (per channel, up to sampling)."""
    env = np.asarray(latlong, np.float64)[..., :3]
    h, w = env.shape[:2]
    omega = (2.0 * np.pi / w) * (np.pi / h) * np.sin((np.arange(h) + 0.5) / h * np.pi)[:, None]
    luma = np.maximum(env @ LUMA, 0.0)
    power = luma * omega
    total = float(power.sum())
    if total <= 0:
        return LightSamples(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int), np.zeros(0))
    bright = luma > BRIGHT_FACTOR * max(weighted_median(luma.ravel(), np.broadcast_to(omega, luma.shape).ravel()),
                                        1e-12)
    dirs, weights, sides, omegas = [], [], [], []
    for mask, n, side in ((bright, bright_samples, BRIGHT_MAP), (~bright, sky_samples, SKY_MAP)):
        p = np.where(mask, power, 0.0)
        part = float(p.sum())
        if part <= 1e-6 * total or n <= 0:
            continue
        rows, cols = _sample_texels(p, n)
        texel = rows, np.minimum(cols.astype(int), w - 1)
        colour = env[texel] / np.maximum(luma[texel], 1e-30)[:, None]  # chosen by luminance: RGB over it
        dirs.append(_latlong_direction(rows, cols, h, w))
        weights.append(colour * (part / n))
        sides.append(np.full(n, side))
        omegas.append((part / n) / np.maximum(luma[texel], 1e-30))  # the sample's power over its radiance
    return LightSamples(*(np.concatenate(x) for x in (dirs, weights, sides, omegas)))


def _tangents(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to unit ``d`` and to each other (any rotation about d)."""
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = np.cross(d, a)
    t /= np.linalg.norm(t)
    return t, np.cross(d, t)


def disc_samples(direction, irradiance, angle_deg: float, n: int = LIGHT_SAMPLES) -> LightSamples:
    """A distant light (a Blender sun: ``direction`` toward it, RGB ``irradiance`` at normal incidence, apparent
    diameter ``angle_deg``) as ``n`` samples spread evenly over its disc (a Vogel spiral)."""
    d = np.asarray(direction, np.float64)
    d /= np.linalg.norm(d)
    half = np.radians(max(float(angle_deg), 0.0)) / 2.0
    n = n if half > 0 else 1
    k = np.arange(n)
    r = np.tan(half) * np.sqrt((k + 0.5) / n)
    a = k * np.pi * (3.0 - np.sqrt(5.0))
    t, b = _tangents(d)
    dirs = d + r[:, None] * (np.cos(a)[:, None] * t + np.sin(a)[:, None] * b)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    w = np.tile(np.asarray(irradiance, np.float64) / n, (n, 1))
    omega = 2.0 * np.pi * (1.0 - np.cos(half)) / n
    return LightSamples(dirs, w, np.full(n, BRIGHT_MAP), np.full(n, omega))


def sample_scale(triangles: int) -> float:
    """The share of the full sample counts a frame with ``triangles`` casters affords: each sample rasterises
    them all once (about 2 us a triangle in numpy), so past TRIANGLE_BUDGET triangle-maps the counts shrink, to
    no fewer than an eighth: shadows stay, softer steps in their penumbrae."""
    full = BRIGHT_SAMPLES + SKY_SAMPLES
    return float(np.clip(TRIANGLE_BUDGET / max(triangles * full, 1), 0.125, 1.0))


def light_samples(latlong: np.ndarray | None, strength: float = 1.0, lights: list[dict] = (),
                  scale: float = 1.0) -> LightSamples:
    """The samples of a probe's light: its environment (``latlong`` times ``strength``; None: none) and the
    lights split off it (dicts with direction, irradiance, angle, as probe.json's "lights" and the suns a bake
    makes); ``scale`` times the usual counts (sample_scale)."""
    def n(count: int) -> int:
        return max(4, int(round(count * scale)))
    parts = []
    if latlong is not None and strength > 0:
        env = environment_samples(latlong, n(BRIGHT_SAMPLES), n(SKY_SAMPLES))
        parts.append(LightSamples(env.directions, env.weights * strength, env.map_sides, env.solid_angles))
    parts += [disc_samples(li["direction"], li["irradiance"], li.get("angle", 0.0), n(LIGHT_SAMPLES))
              for li in lights]
    parts = [p for p in parts if p.count]
    if not parts:
        return LightSamples(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int), np.zeros(0))
    return LightSamples(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                          ("directions", "weights", "map_sides", "solid_angles")))


# ---- receivers ----

def camera_rays(cam_to_world, tan_x: float, tan_y: float, width: int, height: int, cx: float = 0.0,
                cy: float = 0.0, window=None, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(rays (h, w, 3), origin (3,)): per pixel centre of the window (every ``step``-th pixel, starting at the
    middle of each block) the world direction whose component along the view axis is 1, so that a point at
    planar depth z is origin + z ray; the camera model of mesh_depth (rows top first)."""
    from .mesh_depth import camera_basis
    b = camera_basis(cam_to_world)
    x0, y0, x1, y1 = (0, 0, int(width), int(height)) if window is None else (int(v) for v in window)
    off = (step - 1) // 2
    i = x0 + np.arange(off, x1 - x0, step) + 0.5
    j = y0 + np.arange(off, y1 - y0, step) + 0.5
    s = (i / width * 2.0 - 1.0) * tan_x + cx  # right
    t = (j / height * 2.0 - 1.0) * tan_y - cy  # down
    right, up, fwd = b[:3, 0], b[:3, 1], -b[:3, 2]
    rays = fwd + s[None, :, None] * right + t[:, None, None] * (-up)
    return rays, b[:3, 3].copy()


def surface_points(depth: np.ndarray, rays: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points (h, w, 3), normals (h, w, 3)) of a planar depth image on its rays; each normal from the cross
    product of the smaller one-sided differences across and down, turned toward the camera; NaN where the depth
    or a neighbour is missing (depth <= 0 or not finite)."""
    z = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan).astype(np.float64)
    p = origin + z[..., None] * rays

    def smaller(axis):
        fwd = np.diff(p, axis=axis, append=np.nan)
        bwd = np.diff(p, axis=axis, prepend=np.nan)
        take_bwd = ~(np.linalg.norm(fwd, axis=-1) <= np.linalg.norm(bwd, axis=-1))  # NaN forward: backward
        take_bwd &= np.isfinite(bwd).all(-1)
        return np.where(take_bwd[..., None], bwd, fwd)
    n = np.cross(smaller(0), smaller(1))  # down x right: toward the camera on a surface facing it (fixed below)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    flip = (n * rays).sum(-1) > 0
    n = np.where(flip[..., None], -n, n)
    return p, n


# ---- visibility ----

def visibility(points: np.ndarray, normals: np.ndarray, tris: np.ndarray, direction: np.ndarray,
               side: int, spread: float = 0.0) -> np.ndarray:
    """(N,) in [0, 1]: how open the way from each point (N, 3) along ``direction`` is past ``tris``: a shadow map
    of ``side`` texels over where the meshes' and the points' footprints along the light overlap (each point moved
    one texel along its normal first).

    ``spread``: the sample's angular radius (radians; a sky sample stands for a patch of sky, not a point). A point
    beyond every mesh along the light sees the meshes' coverage averaged over a square of the patch's area at its
    distance past the meshes' far end, read from a summed-area table, once that square is wider than SOFT_FROM
    texels: its shadow softens with distance as the patch's would, and far receivers get one soft shadow per sample
    instead of a sharp copy each. Points among or near the meshes (contact) take the 2x2 percentage-closer filter
    of the depth comparison."""
    fwd = -np.asarray(direction, np.float64)
    t, b = _tangents(fwd)
    basis = np.stack([t, b, fwd])
    vis = np.ones(len(points))
    verts = tris.reshape(-1, 3) @ basis.T
    z_hi = verts[:, 2].max()  # the meshes' end farthest along the light
    tan = np.tan(min(max(spread, 0.0), 1.2)) * 0.5 * np.sqrt(np.pi)  # a square of the patch's disc's area
    d_all = points @ basis[2]
    reach = max(float((d_all.max() - z_hi) * tan), 0.0)  # the widest soft square's half-width
    uv_p = points @ basis[:2].T
    lo = np.maximum(verts[:, :2].min(0), uv_p.min(0) - reach)
    hi = np.minimum(verts[:, :2].max(0), uv_p.max(0) + reach)
    if np.any(hi < lo):  # no point in the meshes' shadow
        return vis
    size = np.maximum(hi - lo, 1e-9)
    texel = max(size.max() / side, 1e-9)
    lo, hi = lo - 2 * texel, hi + 2 * texel  # whole texels round the footprint for the filter
    w, h = (int(np.ceil(v)) for v in (hi - lo) / texel)
    u0, v0, u1, v1 = lo[0], lo[1], lo[0] + w * texel, lo[1] + h * texel
    zmap = rasterise_ortho(tris, basis, (u0, v0, u1, v1), w, h).astype(np.float64)
    q = points + normals * texel
    x = (q @ basis[0] - u0) / texel - 0.5  # continuous texel coordinates (centres at integers)
    y = (v1 - q @ basis[1]) / texel - 0.5
    d = q @ basis[2]
    bias = 2.0 * texel
    half = np.maximum(d - z_hi, 0.0) * tan / texel  # the soft square's half-width, texels (from the meshes' end
    # nearest the point: the least blur a point behind them all can have)
    soft = (d > z_hi + bias) & (half > SOFT_FROM)
    inside = (x > -1 - half) & (x < w + half) & (y > -1 - half) & (y < h + half)
    hard = inside & ~soft
    if hard.any():
        xi, yi, di = x[hard], y[hard], d[hard]
        fx, fy = np.floor(xi), np.floor(yi)
        ax, ay = xi - fx, yi - fy
        pad = np.pad(zmap, 1, constant_values=np.inf)
        out = np.zeros(len(xi))
        for dx, dy, wgt in ((0, 0, (1 - ax) * (1 - ay)), (1, 0, ax * (1 - ay)), (0, 1, (1 - ax) * ay),
                            (1, 1, ax * ay)):
            zz = pad[np.clip((fy + dy).astype(int) + 1, 0, h + 1), np.clip((fx + dx).astype(int) + 1, 0, w + 1)]
            out += wgt * (zz >= di - bias)
        vis[hard] = out
    soft &= inside
    if soft.any():  # behind every mesh: all of their texels occlude, so the coverage's box mean is the shadow
        sat = np.zeros((h + 1, w + 1))
        sat[1:, 1:] = np.isfinite(zmap).cumsum(0).cumsum(1)
        xs, ys, r = x[soft] + 0.5, y[soft] + 0.5, half[soft]  # texel edges at integers

        def at(yy, xx):
            return sat[np.clip(np.rint(yy), 0, h).astype(int), np.clip(np.rint(xx), 0, w).astype(int)]
        y0, y1, x0, x1 = ys - r, ys + r, xs - r, xs + r
        area = (2 * r) ** 2
        covered = at(y1, x1) - at(y0, x1) - at(y1, x0) + at(y0, x0)
        vis[soft] = 1.0 - np.clip(covered / area, 0.0, 1.0)
    return vis


def bounce(samples: LightSamples, albedo) -> np.ndarray:
    """(K, 3) what a diffuse mesh of RGB ``albedo`` in front of each sample gives back instead of it: its radiance
    albedo E(-l_k) / pi (its face toward the receiver lit by the probe's light, unshadowed) over the sample's solid
    angle. Zero for a black mesh: then the shadow is the blocked light alone."""
    a = np.asarray(albedo, np.float64)
    irr = np.maximum(-samples.directions @ samples.directions.T, 0.0) @ samples.weights  # E(-l_k), (K, 3)
    return a * irr / np.pi * samples.solid_angles[:, None]


def shadow_ratio(points: np.ndarray, normals: np.ndarray, tris: np.ndarray, samples: LightSamples,
                 albedo=(0.0, 0.0, 0.0), chunk: int = 1 << 15) -> np.ndarray:
    """(N, 3) per RGB channel the share of the light reaching each point (N, 3) with normal (N, 3) that ``tris``
    (m, 3, 3) leave: 1 where nothing blocks it; 1 for points without a normal (NaN). A blocked sample's light is
    replaced by what the mesh reflects toward the point (``bounce``: diffuse, of RGB ``albedo``); never above 1.

    The light without meshes, sum_k max(0, n . l_k) L_k, is one matrix product; what the meshes block is looked up
    only for the points whose way to a sample passes the meshes' bounding sphere (most points, for most samples,
    are not in any shadow)."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    ok = np.isfinite(pts).all(1) & np.isfinite(nrm).all(1)
    ratio = np.ones((len(pts), 3))
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    if not len(tris) or not samples.count or not ok.any():
        return ratio
    p, n = pts[ok], nrm[ok]
    dirs, weights = samples.directions, samples.weights
    n32, d32, w32 = n.astype(np.float32), dirs.T.astype(np.float32), weights.astype(np.float32)  # 3x float64's speed
    den = np.concatenate([np.maximum(n32[i:i + chunk] @ d32, 0.0) @ w32 for i in range(0, len(n), chunk)])
    den = den.astype(np.float64)
    verts = tris.reshape(-1, 3)
    centre = 0.5 * (verts.min(0) + verts.max(0))
    radius = float(np.sqrt(((verts - centre) ** 2).sum(1).max())) * 1.01 + 1e-6
    v = centre - p
    vv = (v * v).sum(1)
    blocked = np.zeros((len(p), 3))
    lost = weights - bounce(samples, albedo)  # per sample: what a mesh in front of it takes
    spreads = np.sqrt(samples.solid_angles / np.pi)  # each sample's patch as a disc: its angular radius
    for d, wgt, side, spread in zip(dirs, lost, samples.map_sides, spreads):
        t = v @ d  # along the way to the light, to the sphere's centre
        r = radius + np.maximum(t, 0.0) * np.tan(min(spread, 1.2)) * 1.26  # the soft square's corner (visibility)
        near = np.where(t > 0, vv - t * t, vv) < r * r
        idx = np.nonzero(near)[0]
        if not len(idx):
            continue
        cos = n[idx] @ d
        idx, cos = idx[cos > 0], cos[cos > 0]
        if not len(idx):
            continue
        vis = visibility(p[idx], n[idx], tris, d, int(side), float(spread))
        blocked[idx] += ((1.0 - vis) * cos)[:, None] * wgt
    ratio[ok] = np.where(den > 0, 1.0 - blocked / np.where(den > 0, den, 1.0), 1.0)
    return np.clip(ratio, 0.0, 1.0)


# ---- a frame ----

def _upsample(ratio_lo: np.ndarray, z_lo: np.ndarray, z: np.ndarray, step: int) -> np.ndarray:
    """Full-size (H, W, 3) ratio from the grid of every ``step``-th pixel (block middles): bilinear over the four
    nearest grid samples, those whose depth is not within DEPTH_TOLERANCE of the pixel's own all but left out
    (joint bilateral), so a shadow on the floor does not bleed onto a nearer object. Pixels of one phase (the same
    place within their block) share their bilinear weights and their samples are shifted copies of the grid, so
    the work is step^2 x 4 whole-grid array operations, no gathers."""
    h, w = z.shape
    off = (step - 1) // 2
    zp = np.pad(z_lo.astype(np.float32), 1, mode="edge")  # the grid's edge repeated: clamped taps
    rp = np.pad(ratio_lo.astype(np.float32), ((1, 1), (1, 1), (0, 0)), mode="edge")
    out = np.empty((h, w, 3), np.float32)
    for a in range(min(step, h)):
        ya = int(np.floor((a - off) / step))
        fy = np.float32((a - off) / step - ya)
        for b in range(min(step, w)):
            xb = int(np.floor((b - off) / step))
            fx = np.float32((b - off) / step - xb)
            zf = z[a::step, b::step].astype(np.float32)
            ka, kb = zf.shape
            tol = np.float32(DEPTH_TOLERANCE) * np.abs(zf)
            acc = np.zeros((ka, kb, 3), np.float32)
            wsum = np.zeros((ka, kb), np.float32)
            for dy in (0, 1):
                for dx in (0, 1):
                    y, x = 1 + ya + dy, 1 + xb + dx
                    bil = (fy if dy else 1 - fy) * (fx if dx else 1 - fx)
                    same = np.abs(zp[y:y + ka, x:x + kb] - zf) <= tol  # NaN (no surface) is never the same
                    wgt = np.where(same, bil, np.float32(1e-6) * bil)
                    acc += wgt[..., None] * rp[y:y + ka, x:x + kb]
                    wsum += wgt
            out[a::step, b::step] = acc / np.maximum(wsum, np.float32(1e-30))[..., None]
    return out


def frame_ratio(depth: np.ndarray, alpha: np.ndarray, tris, samples: LightSamples, cam_to_world, tan_x: float,
                tan_y: float, width: int, height: int, cx: float = 0.0, cy: float = 0.0, window=None,
                max_side: int = MAX_SIDE, albedo=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(H, W, 3) the shadow ratio of a camera frame's splat pixels (the window's, as the renderer gave ``depth``
    and the splats' coverage ``alpha``): 1 where the coverage is under MIN_ALPHA, no mesh blocks the light, or no
    light is given. Computed on every ``step``-th pixel where the window's larger side passes ``max_side``.
    ``albedo``: the meshes' diffuse colour, for the light they reflect into their own shadow (shadow_ratio)."""
    depth = np.asarray(depth, np.float64)
    h, w = depth.shape
    ones = np.ones((h, w, 3), np.float32)
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    covered = (np.asarray(alpha) >= MIN_ALPHA) & (depth > 0)
    if not len(tris) or not samples.count or not covered.any():
        return ones
    step = max(1, int(np.ceil(max(h, w) / max_side)))
    z = np.where(covered, depth, np.nan)
    off = (step - 1) // 2
    z_lo = z[off::step, off::step]
    rays, origin = camera_rays(cam_to_world, tan_x, tan_y, width, height, cx, cy, window, step)
    hl, wl = z_lo.shape
    p, n = surface_points(z_lo, rays, origin)
    ratio = shadow_ratio(p.reshape(-1, 3), n.reshape(-1, 3), tris, samples, albedo).reshape(hl, wl, 3)
    ratio = ratio.astype(np.float32)
    if step > 1:
        ratio = _upsample(ratio, z_lo, z, step)
    return np.where(covered[..., None], ratio, 1.0).astype(np.float32)


def apply(front: np.ndarray, behind: np.ndarray, ratio: np.ndarray, no_mesh: np.ndarray,
          strength: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """FRONT and BEHIND with the capture's surface shadowed: FRONT where no mesh covers the pixel (it holds all
    the splats there), BEHIND where one does (seen at the mesh's anti-aliased edges and through it); colour only,
    coverage kept. ``strength`` 0..1 scales the darkening."""
    r = 1.0 - float(strength) * (1.0 - np.asarray(ratio, np.float32))
    front, behind = front.copy(), behind.copy()
    m = np.asarray(no_mesh, bool)
    front[m, :3] *= r[m]
    behind[~m, :3] *= r[~m]
    return front, behind
