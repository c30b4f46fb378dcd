"""A level of detail for probes: merged splats over a regular octree, built once per scene, and the cut a probe
renders from it.

Tree. A cube over the scene's bounds (robust: the 0.05/99.95 percentiles; splats outside it are never merged and
always drawn) is split into 2^b cells per axis at level 1 and halved going up, level L's cell being
``cell1 * 2^(L-1)`` wide. Level 0 are the splats. A level-L node merges everything in one occupied cell by moment
matching: weight w = opacity x mean footprint area (the integral of the coverage a ray sees, averaged over view
directions), mean and covariance = the weighted mean and the weighted second moment about it, colour = the
weighted mean of every SH coefficient (of the light: an sRGB scene's colours are decoded first), and an opacity
whose footprint integral is the children's summed weight
(a Gaussian saturating at ALPHA_MAX keeps the integral with opacity > 1: ``o = a * exp(W / (a A) - 1)``, so an
opaque wall stays opaque instead of turning into a lattice of half-transparent blobs). A cell holding a single
child repeats that child exactly and is not stored; a node's ``parent_level`` is its nearest stored ancestor.

Cut. A node's error err(n) = size(n) / dist(probe, box(n)) (0 for a splat, infinite with the probe inside the box)
grows up the tree (a parent's box holds its child's and is twice as wide), so "draw n iff err(n) <= tau and
err(parent(n)) > tau" picks exactly one node on every path from a splat to the root: no gaps, no double counting.
tau = k x the probe's pixel angle. Boxes follow from (level, cell), so gs_preprocess.comp makes the same choice per
node with no host work; ``cut()`` here is its reference.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..colour import srgb_to_linear
from ..scene import SH_C0, SplatScene, quat_to_matrix
from .splat_math import ALPHA_MAX

NO_PARENT = 255  # parent_level of a node no stored node contains: its parent's error is infinite
MAX_LEVEL1_BITS = 15  # at most 2^15 cells per axis at level 1 (coordinates travel in 16 bits)
LEVEL1_CELL_SPLATS = 4.0  # level-1 cells are this many median splat sizes (largest scale) wide
MAX_MERGED_OPACITY = float(ALPHA_MAX * np.exp(4.0))  # saturated core up to ~5x the 1/e radius: enough for walls
DEFAULT_LOD_K = 1.0  # tau = k x pixel angle: a node is drawn once its cell spans at most k pixels


def mean_footprint(scales: np.ndarray) -> np.ndarray:
    """2 pi sqrt(mean over the three axes of the projected determinant): the area of the Gaussian's footprint, in
    the sense that a ray-evaluated splat of opacity o (unsaturated) covers o times this, averaged over views."""
    q = np.asarray(scales, np.float64) ** 2
    return 2 * np.pi * np.sqrt((q[:, 0] * q[:, 1] + q[:, 0] * q[:, 2] + q[:, 1] * q[:, 2]) / 3.0)


def _ein(t: np.ndarray) -> np.ndarray:
    """Ein(t) = integral_0^t (1 - e^-x) / x dx: the footprint integral (in units of the area) of the coverage
    1 - exp(-t g) of a Gaussian optical depth of peak t."""
    t = np.asarray(t, np.float64)
    small = t < 12.0
    ts = np.where(small, t, 0.0)
    series = np.zeros_like(t)
    term = np.ones_like(t)
    for k in range(1, 90):  # sum (-1)^(k+1) t^k / (k k!)
        term = term * ts / k
        series += (-1) ** (k + 1) * term / k
    # large t: ln t + gamma + E1(t), E1(t) ~ e^-t / t (1 - 1/t + 2/t^2)
    tl = np.where(small, 12.0, t)
    large = np.log(tl) + 0.5772156649015329 + np.exp(-tl) / tl * (1 - 1 / tl + 2 / tl ** 2 - 6 / tl ** 3)
    return np.where(small, series, large)


def opacity_for_weight(weight: np.ndarray, area: np.ndarray) -> np.ndarray:
    """The merged opacity. The children are taken as a random medium: optical depth t = weight / area in the
    merged Gaussian's profile, whose coverage integral is area * Ein(t) (= weight while the cluster is thin, far
    less once its splats hide each other: the back of a closed shell is not seen). The rendered splat of opacity
    o (alpha capped at ALPHA_MAX) covers area * o below the cap and area * a (1 + ln(o / a)) above; o matches the
    two."""
    c = _ein(weight / np.maximum(area, 1e-300))
    sat = ALPHA_MAX * np.exp(np.minimum(c / ALPHA_MAX - 1.0, 50.0))
    return np.minimum(np.where(c <= ALPHA_MAX, c, sat), MAX_MERGED_OPACITY)


def matrix_to_quat_batch(r: np.ndarray) -> np.ndarray:
    """(N, 3, 3) proper rotations -> (N, 4) unit quaternions (w, x, y, z), inverse of scene.quat_to_matrix."""
    m = np.asarray(r, np.float64)
    t = np.trace(m, axis1=1, axis2=2)
    q = np.empty((len(m), 4))
    # one of four formulas per row, picked by the largest diagonal term (numerically safe)
    cases = np.argmax(np.stack([t, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], 1), 1)
    for c in range(4):
        s = cases == c
        if not s.any():
            continue
        a = m[s]
        if c == 0:
            k = np.sqrt(np.maximum(1.0 + t[s], 1e-300)) * 2
            q[s] = np.stack([0.25 * k, (a[:, 2, 1] - a[:, 1, 2]) / k, (a[:, 0, 2] - a[:, 2, 0]) / k,
                             (a[:, 1, 0] - a[:, 0, 1]) / k], 1)
        else:
            i = c - 1
            j, l = (i + 1) % 3, (i + 2) % 3
            k = np.sqrt(np.maximum(1.0 + a[:, i, i] - a[:, j, j] - a[:, l, l], 1e-300)) * 2
            v = np.empty((len(a), 4))
            v[:, 0] = (a[:, l, j] - a[:, j, l]) / k
            v[:, 1 + i] = 0.25 * k
            v[:, 1 + j] = (a[:, j, i] + a[:, i, j]) / k
            v[:, 1 + l] = (a[:, l, i] + a[:, i, l]) / k
            q[s] = v
    return q / np.linalg.norm(q, axis=1, keepdims=True)


_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the covariance's six entries


# An sRGB scene's colours are merged as the light they stand for (core/colour.py): averaging the encoded values
# darkens a cluster whose children differ in brightness (the curve is convex; the guitar capture's irradiance fell
# 23% at k = 0.5). The DC colour is decoded to linear radiance before the weighted mean and encoded again after; the
# higher bands, small view-dependent changes of the encoded colour, go through the curve's slope at the DC colour.
def _srgb_encode(x: np.ndarray) -> np.ndarray:
    """The inverse of colour.srgb_to_linear on x >= 0 (no clamp above 1: the extended curve)."""
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def _srgb_slope(c: np.ndarray) -> np.ndarray:
    """d srgb_to_linear / dc."""
    c = np.asarray(c, np.float64)
    return np.where(c < 0.04045, np.where(c > 0.0, 1.0 / 12.92, 0.0),
                    2.4 / 1.055 * np.power((np.maximum(c, 0.04045) + 0.055) / 1.055, 1.4))


def _sh_to_linear(sh: np.ndarray) -> np.ndarray:
    """(N, K, 3) SH of sRGB-encoded colour -> the same layout in linear radiance (DC: the decoded colour itself)."""
    c = SH_C0 * sh[:, 0].astype(np.float64) + 0.5
    out = sh.astype(np.float64) * _srgb_slope(c)[:, None, :]
    out[:, 0] = srgb_to_linear(c)
    return out


def _sh_from_linear(lin: np.ndarray) -> np.ndarray:
    """The inverse of _sh_to_linear."""
    c = _srgb_encode(lin[:, 0])
    out = lin / np.maximum(_srgb_slope(c), 1e-12)[:, None, :]
    out[:, 0] = (c - 0.5) / SH_C0
    return out


@dataclass
class _Moments:
    """Weighted sums of a set of nodes (one row per node): what merging adds up."""
    w: np.ndarray  # (M,) total weight
    m1: np.ndarray  # (M, 3) sum of w * mean
    m2: np.ndarray  # (M, 6) sum of w * (cov + mean mean^T), entries _PAIRS
    sh: np.ndarray  # (M, K*3) sum of w * sh

    def merged(self, inverse: np.ndarray, count: int) -> "_Moments":
        def add(x: np.ndarray) -> np.ndarray:
            if x.ndim == 1:
                return np.bincount(inverse, x, count)
            return np.stack([np.bincount(inverse, x[:, c], count) for c in range(x.shape[1])], 1)
        return _Moments(add(self.w), add(self.m1), add(self.m2), add(self.sh))


@dataclass
class LodTree:
    """All nodes of one scene's level of detail, splats first (in their storage order), then merged nodes.

    ``scene`` holds every node as a splat (what the renderer uploads); ``level`` is 0 for splats; ``cell`` the
    node's cell at level max(level, 1) (a splat: the level-1 cell of its centre); ``parent_level`` the level of the
    nearest stored node containing it (NO_PARENT: none, or a splat outside the grid).
    """
    scene: SplatScene
    leaves: int
    level: np.ndarray  # (M,) uint8
    parent_level: np.ndarray  # (M,) uint8
    cell: np.ndarray  # (M, 3) int32
    origin: np.ndarray  # (3,) float64, the grid's corner
    cell1: float  # level-1 cell size
    levels: int  # the top level (one cell)
    build_s: float = 0.0

    @property
    def count(self) -> int:
        return self.scene.count

    def words(self) -> np.ndarray:
        """(M, 2) uint32 per node for the GPU: x = cell x | cell y << 16, y = cell z | level << 16 | parent << 24."""
        c = self.cell.astype(np.uint32)
        return np.stack([c[:, 0] | (c[:, 1] << 16),
                         c[:, 2] | (self.level.astype(np.uint32) << 16) | (self.parent_level.astype(np.uint32) << 24)],
                        1)

    def counts_by_level(self) -> dict[int, int]:
        lv, n = np.unique(self.level, return_counts=True)
        return {int(a): int(b) for a, b in zip(lv, n)}


def _cell_error_ok(origin: np.ndarray, cell1: float, level: np.ndarray, cell_at: np.ndarray, probe: np.ndarray,
                   tau: float) -> np.ndarray:
    """size <= tau * dist(probe, box) for cells (level >= 1, coordinates at that level): the node is fine enough."""
    size = cell1 * np.exp2(level.astype(np.float64) - 1.0)
    lo = origin + cell_at * size[:, None]
    d = np.maximum(np.maximum(lo - probe, probe - (lo + size[:, None])), 0.0)
    return size <= tau * np.sqrt(np.sum(d * d, 1))


def cut(tree: LodTree, probe, tau: float) -> np.ndarray:
    """(M,) bool: the nodes a probe at ``probe`` draws with threshold ``tau`` (radians); the reference of the
    choice gs_preprocess.comp makes. tau = 0 draws the splats only."""
    p = np.asarray(probe, np.float64).reshape(3)
    lvl = tree.level.astype(np.int64)
    plv = tree.parent_level.astype(np.int64)
    base = np.maximum(lvl, 1)  # the level the stored cell is at
    own = np.ones(tree.count, bool)
    m = lvl > 0
    own[m] = _cell_error_ok(tree.origin, tree.cell1, lvl[m], tree.cell[m].astype(np.float64), p, tau)
    coarse = np.ones(tree.count, bool)  # parent's error > tau
    m = plv != NO_PARENT
    pc = (tree.cell[m].astype(np.int64) >> (plv[m] - base[m])[:, None]).astype(np.float64)
    coarse[m] = ~_cell_error_ok(tree.origin, tree.cell1, plv[m], pc, p, tau)
    return own & coarse


def _grid(scene: SplatScene) -> tuple[np.ndarray, float, int]:
    pos = scene.positions.astype(np.float64)
    lo, hi = np.percentile(pos, [0.05, 99.95], axis=0) if len(pos) > 2000 else (pos.min(0), pos.max(0))
    extent = float(np.max(hi - lo))
    extent = max(extent * 1.0001, 1e-6)
    size = float(np.median(scene.scales.max(1))) * LEVEL1_CELL_SPLATS
    bits = int(np.clip(np.ceil(np.log2(extent / max(size, extent / 2 ** MAX_LEVEL1_BITS))), 1, MAX_LEVEL1_BITS))
    return lo - 0.5 * (extent - (hi - lo)), extent / 2 ** bits, bits  # a cube centred on the bounds


def _moments_of_splats(scene: SplatScene, sel: np.ndarray) -> tuple[_Moments, np.ndarray]:
    # Millions of splats (a capture's motion copy, coarse.py; a tree): only the covariance's six entries are formed,
    # and the SH, the largest part, stay float32 per splat (np.bincount sums them in float64 when merging): the
    # (N, 3, 3) covariances and a float64 copy of the SH took most of a 3M-splat copy's build.
    rot = quat_to_matrix(scene.rotations[sel])
    q = scene.scales[sel].astype(np.float64) ** 2
    w = scene.opacities[sel].astype(np.float64) * mean_footprint(scene.scales[sel])
    mu = scene.positions[sel].astype(np.float64)
    m2 = np.stack([w * (np.sum(rot[:, i] * rot[:, j] * q, 1) + mu[:, i] * mu[:, j]) for i, j in _PAIRS], 1)
    sh = scene.sh if sel.all() else scene.sh[sel]  # a boolean selection copies (N, K, 3) floats: not when all
    if scene.colour_space == "srgb":
        sh = _sh_to_linear(sh).astype(np.float32)
    shared = sh is scene.sh  # the scene's own array is weighted into a new one, a copy of ours in place
    sh, weight = sh.reshape(len(w), -1), w.astype(np.float32)[:, None]
    sh = sh * weight if shared else np.multiply(sh, weight, out=sh)
    return _Moments(w, mu * w[:, None], m2, sh), w


def _splats_of(mom: _Moments, sh_k: int, srgb: bool) -> tuple[np.ndarray, ...]:
    """Means, scales, quaternions, opacities, SH of merged nodes from their sums (``srgb``: the sums are of linear
    colour, returned encoded)."""
    w = np.maximum(mom.w, 1e-300)
    mu = mom.m1 / w[:, None]
    cov = np.empty((len(w), 3, 3))
    for k, (i, j) in enumerate(_PAIRS):
        cov[:, i, j] = cov[:, j, i] = mom.m2[:, k] / w - mu[:, i] * mu[:, j]
    evals, evecs = np.linalg.eigh(cov)
    evecs[np.linalg.det(evecs) < 0, :, 0] *= -1  # a proper rotation
    # a merged disk stays flat, but not flatter than 1e-3 of its width (the whitening transform stays finite)
    scales = np.sqrt(np.maximum(evals, 1e-6 * np.maximum(evals[:, 2:], 1e-30)))
    opacity = opacity_for_weight(mom.w, mean_footprint(scales))
    sh = (mom.sh / w[:, None]).reshape(len(w), sh_k, 3)
    return mu, scales, matrix_to_quat_batch(evecs), opacity, _sh_from_linear(sh) if srgb else sh


def build_lod(scene: SplatScene) -> LodTree:
    """The level of detail of ``scene`` (vectorised numpy; 1M splats take a few seconds)."""
    t0 = time.perf_counter()
    n, sh_k = scene.count, scene.sh.shape[1]
    origin, cell1, bits = _grid(scene)
    c1 = np.floor((scene.positions.astype(np.float64) - origin) / cell1).astype(np.int64)
    inside = np.all((c1 >= 0) & (c1 < 2 ** bits), 1)
    c1 = np.where(inside[:, None], c1, 0)
    leaf_parent = np.full(n, NO_PARENT, np.int64)
    mom, _ = _moments_of_splats(scene, inside)
    # per level: cells (coordinates), how many children each holds, map child -> cell
    keys = (c1[inside, 0] << 32) | (c1[inside, 1] << 16) | c1[inside, 2]
    levels: list[dict] = []
    child_keys = keys
    for _level in range(1, bits + 2):
        ukeys, inverse, _ = np.unique(child_keys, return_inverse=True, return_counts=True)
        children = np.bincount(inverse, minlength=len(ukeys))
        mom = mom.merged(inverse, len(ukeys))
        levels.append({"keys": ukeys, "inverse": inverse, "children": children, "mom": mom})
        if len(ukeys) == 1:
            break
        cx, cy, cz = ukeys >> 32, (ukeys >> 16) & 0xFFFF, ukeys & 0xFFFF
        child_keys = ((cx >> 1) << 32) | ((cy >> 1) << 16) | (cz >> 1)
    top = len(levels)
    # nearest stored level at or above each cell, top down
    above = np.full(1, NO_PARENT, np.int64)  # for the (absent) level above the top
    first: list[np.ndarray] = [None] * (top + 1)
    for li in range(top - 1, -1, -1):
        lv = levels[li]
        up = above[levels[li + 1]["inverse"]] if li + 1 < top else np.full(len(lv["keys"]), NO_PARENT, np.int64)
        lv["parent"] = up
        first[li] = np.where(lv["children"] >= 2, li + 1, up)
        above = first[li]
    leaf_parent[inside] = first[0][levels[0]["inverse"]]
    # stored nodes: cells with >= 2 children
    pos, scl, rot, opa, shs, lvl, plv, cells = [], [], [], [], [], [], [], []
    for li, lv in enumerate(levels):
        keep = lv["children"] >= 2
        if not keep.any():
            continue
        sub = _Moments(lv["mom"].w[keep], lv["mom"].m1[keep], lv["mom"].m2[keep], lv["mom"].sh[keep])
        mu, s, q, o, sh = _splats_of(sub, sh_k, scene.colour_space == "srgb")
        k = lv["keys"][keep]
        pos.append(mu)
        scl.append(s)
        rot.append(q)
        opa.append(o)
        shs.append(sh)
        lvl.append(np.full(len(k), li + 1))
        plv.append(lv["parent"][keep])
        cells.append(np.stack([k >> 32, (k >> 16) & 0xFFFF, k & 0xFFFF], 1))
    f32 = np.float32
    all_scene = SplatScene(
        np.concatenate([scene.positions.astype(f32)] + [p.astype(f32) for p in pos]),
        np.concatenate([scene.scales.astype(f32)] + [s.astype(f32) for s in scl]),
        np.concatenate([scene.rotations.astype(f32)] + [q.astype(f32) for q in rot]),
        np.concatenate([scene.opacities.astype(f32)] + [o.astype(f32) for o in opa]),
        np.concatenate([scene.sh.astype(f32)] + [s.astype(f32) for s in shs]),
        source=f"{scene.source} (level of detail)", colour_space=scene.colour_space)
    return LodTree(all_scene, n,
                   np.concatenate([np.zeros(n, np.int64)] + lvl).astype(np.uint8),
                   np.concatenate([leaf_parent] + plv).astype(np.uint8),
                   np.concatenate([c1] + cells).astype(np.int32),
                   origin, float(cell1), top, time.perf_counter() - t0)
