"""The light volume (issue 37): DDGI-style probes on a grid with bricks of finer probes in some of its cells, each
probe an octahedral irradiance map and an octahedral map of distance moments, packed into three float images that
one node group reads at a shading point (EEVEE and Cycles).

This module is the layout and its lookup, the contract with blender/ (docs/architecture.md "Light volume"); the bake
is volume_bake.py, the choice of region and spacing volume_region.py, of the bricks volume_refine.py.

Grid: grid.GridSpec; probe (ix, iy, iz) at spec.points()[ix, iy, iz], linear index i = ix + nx (iy + ny iz).
Cells: cell_shape(spec) = nodes - 1 a side (1 on an axis of one node), cell (cx, cy, cz) between nodes c and c + 1,
linear index c = cx + ncx (cy + ncy cz). A cell holds r = 1 (its eight grid nodes) or a brick of r (BRICK_LEVELS)
with (r + 1)^3 probes of its own, local (lx, ly, lz) at node c + l / r, in the order lx + (r + 1) (ly + (r + 1) lz);
the bricks' probes follow the grid's in the atlases, brick after brick in cell order (brick_bases).

Octahedral map (world directions, Z up): ``oct_encode(d)`` = d.xy / (|x| + |y| + |z|), folded where z < 0 to
(1 - |p.yx|) sign(p.xy) with sign(0) = +1. A map of n x n texels (array [row, column], row 0 at v = -1, the bottom)
has texel (column a, row b) centred at (u, v) = ((a + 0.5) / n 2 - 1, (b + 0.5) / n 2 - 1).

Per probe: ``IRR`` x ``IRR`` texels of E(n)/pi (linear RGB: albedo x value is the diffuse radiance), and ``VIS`` x
``VIS`` texels of (mean r, mean r^2), r the distance in metres from the probe to what it sees, filtered by the lobe
max(0, d.w)^VIS_SHARPNESS (DDGI's), directions with no splats (coverage < COVERED) at the far distance.

Atlas (pack_atlas): probes tiled ``cols = ceil(sqrt(N))`` wide, probe i at tile column i % cols, tile row i // cols,
each tile the map plus one border texel a side ((IRR + 2)^2, (VIS + 2)^2), rows bottom first (as Blender stores
images). Borders repeat the map's texels across the octahedral fold (an edge (1, v) is the same direction as (1, -v),
the four corners are -Z), so a bilinear lookup inside a tile is seamless. Texel lookup for direction d in tile t:
pixel = tile_origin(t) + 1 + (oct_encode(d) 0.5 + 0.5) n, continuous, texel centres at +0.5; u = pixel_x / width,
v = pixel_y / height; bilinear, clamped at the image's edge (Blender's Image Texture: Linear, Extend).
Cells image (pack_cells): one texel a cell, tiled ceil(sqrt(cells)) wide, of (the brick's first probe among the
bricks', r, 0), read at the texel's centre (Closest).

The lookup (sample_packed: the node group's numpy twin, term for term; sample: the same on the unpacked maps):
    P' = P + NORMAL_BIAS s n          s = spec_spacing(spec): the smallest node spacing; n the unit normal
    g  = clamp((P' - lo) / (hi - lo) (shape - 1), 0, shape - 1)      (0 on an axis of one node)
    c  = min(floor(g), max(shape - 2, 0))                            the cell; (base, r) its cells texel
    l0 = min(floor((g - c) r), r - 1), f = (g - c) r - l0            the brick's sub-cell (r = 1: the cell)
    for each of the 8 corners L = l0 + (0 or 1 per axis):
        q_c        = first node + (c + L / r) step                   (the node's place)
        index      = r > 1 ? N + base + Lx + (r + 1) (Ly + (r + 1) Lz) : the grid's index of min(c + L, shape - 1)
        trilinear  = prod over axes (f or 1 - f)
        r          = |P' - q_c|
        (m, m2)    = VIS map of c at P' - q_c                             (+Z where r = 0)
        variance   = max(m2 - m^2, (VARIANCE_FLOOR m)^2)
        cheb       = 1 if r <= m else (variance / (variance + (r - m)^2))^3
        w          = max(cheb, MIN_WEIGHT);  w = w < CRUSH ? w^3 / CRUSH^2 : w
        w         *= trilinear
    E/pi = sum_c w E_c(n) / sum_c w        (E_c(n): IRR map of c at the normal n)
Without visibility (``visibility=False``: the leak's measurement) cheb = 1.

No backface weight: DDGI's ((to_probe . n + 1) / 2)^2 + 0.2 stands for the receiver's own surface hiding probes
behind it, which our probes never see (the lit meshes are not in the splats). It only skews the blend: in the two
rooms (volume_rooms.py, 0.4 m nodes) a sphere's per-point error was 1.5-2.0% mean / 5-10% worst with it, 0.5% / 3%
without; in a gradient shell with exact probes 3.1% / 9.1% against 1.1% / 2.7% (2026-12-05).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np

from .grid import GridSpec, _bilinear  # _bilinear: the texture unit's lookup the SH grid's twin uses too

# Interior texels a side, odd. The octahedral map folds along its axes and its diamond (|u| + |v| = 1), so a smooth
# irradiance has kinks there and a bilinear lookup errs to first order in the texel. The sample room's probes (64^2
# faces, the five places of auto_light_bench; E/pi over 2,000 normals, rms / max relative to the mean): 8^2 texels
# 2.2-7.2% / 9-34%, 16^2 0.7-2.2% / 4.5-17%, 17^2 0.6-1.4% / 4-9% (an odd size puts the axes' kinks on texel
# centres: below the lamp 16^2 read 17% at worst, 17^2 7.8%); order-2 SH 0.9-5.5% / 2.7-13%. Texels fitted to the
# bilinear lookup by least squares (volume_bake.py) instead of point samples: 17^2 0.3-0.6% / 2.8-7.1% (2026-12-05,
# docs/architecture.md "Light volume"). Texels cost the node group nothing (8 lookups whatever the size) and the
# atlas little (361 texels a probe with the border).
IRR = 17
# Visibility's moments follow geometry through a sharp lobe; 17^2 texels of about 12 degrees (DDGI: 16^2), odd for
# the same reason.
VIS = 17
VIS_SHARPNESS = 50.0  # DDGI's depth lobe max(0, d.w)^50: a wall's distance blurred over ~10 degrees
COVERED = 0.5  # a texel whose splat coverage is below this sees nothing: its distance is the far distance
FAR_FACTOR = 4.0  # far distance = FAR_FACTOR x (the volume's diagonal + a spacing): nothing there to block
# x the smallest node spacing: the point moved off its surface along n before the lookup, so a mesh resting on splats
# is seen from above them. Small: a point moved toward a splat wall nears its far side (DDGI's 0.25 of a spacing
# pushed the two rooms' sphere, 0.15 m from the wall, through it: +40% in red).
NORMAL_BIAS = 0.05
VARIANCE_FLOOR = 0.02  # the smallest standard deviation of a distance, relative to its mean (float32-safe)
MIN_WEIGHT = 1e-6
CRUSH = 0.2  # DDGI: weights below this fall off as w^3 (a probe mostly hidden counts as hidden)


@dataclass
class LightVolume:
    """Probes on ``spec``: ``irradiance`` (nx, ny, nz, IRR, IRR, 3) E/pi, ``moments`` (nx, ny, nz, VIS, VIS, 2)
    (mean r, mean r^2) in metres, both octahedral maps [row, column] with row 0 at v = -1."""
    spec: GridSpec
    irradiance: np.ndarray
    moments: np.ndarray
    timings: dict = field(default_factory=dict)
    report: list = field(default_factory=list)  # what the bake chose and why, for the user's report
    # Bricks (volume_refine.py): per cell of the grid (cell_shape), 1 or the r (BRICK_LEVELS) of its brick of
    # (r + 1)^3 probes; None: no bricks. The bricks' maps, brick after brick in cell order, each brick's probes in
    # the order lx + (r + 1) (ly + (r + 1) lz): (B, IRR, IRR, 3) and (B, VIS, VIS, 2).
    refine: np.ndarray | None = None
    brick_irradiance: np.ndarray | None = None
    brick_moments: np.ndarray | None = None

    @property
    def probes(self) -> np.ndarray:
        """(N, 3) the grid's probe positions in linear index order (ix fastest)."""
        return probe_positions(self.spec)

    @property
    def cells(self) -> np.ndarray:
        """(cx, cy, cz) each cell's r (1: the grid's own eight corners)."""
        return np.ones(cell_shape(self.spec), int) if self.refine is None else np.asarray(self.refine, int)

    @property
    def brick_count(self) -> int:
        return 0 if self.brick_irradiance is None else len(self.brick_irradiance)

    @property
    def tiles(self) -> int:
        """Maps in the atlases: the grid's probes, then the bricks'."""
        return self.spec.count + self.brick_count

    def all_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """(tiles, IRR, IRR, 3), (tiles, VIS, VIS, 2): the grid's maps in linear order, then the bricks'."""
        irr, mom = flat_maps(self.irradiance), flat_maps(self.moments)
        if self.brick_count:
            irr = np.concatenate([irr, self.brick_irradiance])
            mom = np.concatenate([mom, self.brick_moments])
        return irr, mom


def probe_positions(spec: GridSpec) -> np.ndarray:
    """(N, 3) positions of ``spec``'s probes in linear index order i = ix + nx (iy + ny iz)."""
    return spec.points().transpose(2, 1, 0, 3).reshape(-1, 3)


# ------------------------------------------------------------------------------------------------------------------
# Octahedral mapping

def _sign(x: np.ndarray) -> np.ndarray:
    return np.where(x >= 0, 1.0, -1.0)


def oct_encode(d: np.ndarray) -> np.ndarray:
    """(..., 3) directions (any length > 0) -> (..., 2) octahedral (u, v) in [-1, 1]^2."""
    d = np.asarray(d, np.float64)
    p = d[..., :2] / np.sum(np.abs(d), -1, keepdims=True)
    folded = (1.0 - np.abs(p[..., ::-1])) * _sign(p)
    return np.where(d[..., 2:3] < 0, folded, p)


def oct_decode(uv: np.ndarray) -> np.ndarray:
    """(..., 2) octahedral (u, v) in [-1, 1]^2 -> (..., 3) unit directions (oct_encode's inverse)."""
    uv = np.asarray(uv, np.float64)
    z = 1.0 - np.abs(uv[..., 0]) - np.abs(uv[..., 1])
    xy = np.where((z < 0)[..., None], (1.0 - np.abs(uv[..., ::-1])) * _sign(uv), uv)
    d = np.concatenate([xy, z[..., None]], -1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def texel_directions(n: int) -> np.ndarray:
    """(n, n, 3) unit directions of an n x n octahedral map's texel centres, [row, column]."""
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    v, u = np.meshgrid(c, c, indexing="ij")
    return oct_decode(np.stack([u, v], -1))


def _wrap(col: np.ndarray, row: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices at most one step outside an n x n map -> the map's texel across the octahedral fold (the border
    rule: past the left or right edge the column stays on the edge and the row mirrors, past the bottom or top the
    row stays and the column mirrors; past a corner the diagonally opposite corner)."""
    out_c = (col < 0) | (col >= n)
    out_r = (row < 0) | (row >= n)
    cc, rc = np.clip(col, 0, n - 1), np.clip(row, 0, n - 1)
    c = np.where(out_c, np.where(out_r, n - 1 - cc, cc), np.where(out_r, n - 1 - col, col))
    r = np.where(out_r, np.where(out_c, n - 1 - rc, rc), np.where(out_c, n - 1 - row, row))
    return c, r


def add_border(maps: np.ndarray) -> np.ndarray:
    """(..., n, n, C) octahedral maps -> (..., n + 2, n + 2, C) with the one-texel border of the fold."""
    maps = np.asarray(maps)
    n = maps.shape[-2]
    idx = np.arange(-1, n + 1)
    rows, cols = np.meshgrid(idx, idx, indexing="ij")
    c, r = _wrap(cols, rows, n)
    return maps[..., r, c, :]


def bilinear_map(maps: np.ndarray, d: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
    """Reference lookup of one map per point, without a border: maps (M, n, n, C), directions (M, 3) -> (M, C),
    bilinear between texel centres with the neighbours across the fold (what the atlas's border gives).
    ``which``: (M,) each point's map among ``maps`` (K, n, n, C) instead (the four texels are gathered from there:
    no (M, n, n, C) copy of whole maps: volume.sample 3x faster, most of the cells' centre errors' time)."""
    maps = np.asarray(maps)
    n = maps.shape[1]
    uv = oct_encode(d)
    x, y = (uv[:, 0] * 0.5 + 0.5) * n - 0.5, (uv[:, 1] * 0.5 + 0.5) * n - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    k = np.arange(len(maps)) if which is None else np.asarray(which)

    def at(cc, rr):
        c, r = _wrap(cc, rr, n)
        return maps[k, r, c].astype(np.float64)
    return ((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0))
            + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1)))


def bilinear_taps(n: int, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The four texels (row-major index, (M, 4)) and weights ((M, 4)) bilinear_map reads for each direction."""
    dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
    uv = oct_encode(dirs)
    x, y = (uv[:, 0] * 0.5 + 0.5) * n - 0.5, (uv[:, 1] * 0.5 + 0.5) * n - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    idx, w = [], []
    for dx, dy, wk in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        c, r = _wrap(x0 + dx, y0 + dy, n)
        idx.append(r * n + c)
        w.append(wk)
    return np.stack(idx, 1), np.stack(w, 1)


def bilinear_matrix(n: int, dirs: np.ndarray) -> np.ndarray:
    """(M, n^2): row m holds the weights bilinear_map gives each texel (row-major) for direction m."""
    idx, w = bilinear_taps(n, dirs)
    out = np.zeros((len(idx), n * n))
    np.add.at(out, (np.arange(len(idx))[:, None], idx), w)
    return out


# ------------------------------------------------------------------------------------------------------------------
# Atlas

def atlas_tiles(count: int) -> tuple[int, int]:
    """(cols, rows) of the atlas of ``count`` probes."""
    cols = max(1, math.ceil(math.sqrt(count)))
    return cols, max(1, -(-count // cols))


def flat_maps(maps: np.ndarray) -> np.ndarray:
    """(nx, ny, nz, n, n, C) -> (N, n, n, C) in linear index order i = ix + nx (iy + ny iz)."""
    return np.asarray(maps).transpose(2, 1, 0, 3, 4, 5).reshape(-1, *maps.shape[3:])


def grid_maps(flat: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """flat_maps' inverse: (N, n, n, C) in linear index order -> (nx, ny, nz, n, n, C)."""
    nx, ny, nz = shape
    return np.asarray(flat).reshape(nz, ny, nx, *flat.shape[1:]).transpose(2, 1, 0, 3, 4, 5)


def _tile(maps: np.ndarray) -> np.ndarray:
    """(N, n, n, C) maps -> the atlas of their bordered tiles (rows (n + 2), cols (n + 2), 3), float32."""
    b = add_border(maps)
    count, t = len(b), b.shape[1]
    cols, rows = atlas_tiles(count)
    rgb = np.zeros((rows * cols, t, t, 3), np.float32)
    rgb[:count, ..., :b.shape[-1]] = b
    return rgb.reshape(rows, cols, t, t, 3).transpose(0, 2, 1, 3, 4).reshape(rows * t, cols * t, 3)


def pack_atlas(volume: LightVolume) -> tuple[np.ndarray, np.ndarray]:
    """The two images the node group reads: irradiance (rows (IRR + 2), cols (IRR + 2), 3) RGB and visibility
    (rows (VIS + 2), cols (VIS + 2), 3) of (mean, mean^2, 0); float32, row 0 at the bottom; the grid's probes,
    then the bricks' (LightVolume.all_maps)."""
    irr, mom = volume.all_maps()
    return _tile(irr), _tile(mom)


# ------------------------------------------------------------------------------------------------------------------
# Cells and bricks

BRICK_LEVELS = (2, 4)  # a brick's r: nested (4's nodes hold 2's), and even (a cell's centre is one of its nodes)
KEY_UNITS = 4  # positions in quarters of a cell: every node of every level on whole numbers (bricks share nodes)


def cell_shape(spec: GridSpec) -> tuple[int, int, int]:
    """Cells a side: nodes - 1 (one on an axis of one node)."""
    return tuple(max(int(n) - 1, 1) for n in spec.shape)


def flat_cells(a: np.ndarray) -> np.ndarray:
    """(cx, cy, cz, ...) -> (C, ...) in linear order c = cx + ncx (cy + ncy cz) (the grid's probe order)."""
    a = np.asarray(a)
    return a.transpose(2, 1, 0, *range(3, a.ndim)).reshape(-1, *a.shape[3:])


def index_grid(shape) -> np.ndarray:
    """(prod(shape), 3) int: every index (i, j, k) below ``shape`` in linear order (i fastest, as flat_cells)."""
    return flat_cells(np.stack(np.meshgrid(*(np.arange(k) for k in shape), indexing="ij"), -1))


def brick_bases(refine: np.ndarray) -> np.ndarray:
    """(cx, cy, cz) each refined cell's first brick probe among the bricks' (0 where r = 1)."""
    r = np.asarray(refine, int)
    size = flat_cells(np.where(r > 1, (r + 1) ** 3, 0))
    base = np.cumsum(size) - size
    c = r.shape
    return base.reshape(c[2], c[1], c[0]).transpose(2, 1, 0)


def node_frame(spec: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """(first node, node step) per axis: node i at first + i step (one node: the box's middle, step 0)."""
    lo, hi, n = (np.asarray(x, np.float64) for x in (spec.lo, spec.hi, spec.shape))
    return np.where(n > 1, lo, (lo + hi) / 2), np.where(n > 1, (hi - lo) / np.maximum(n - 1, 1), 0.0)


@functools.lru_cache(maxsize=None)
def _brick_offsets(r: int) -> np.ndarray:
    out = index_grid((r + 1,) * 3) * (KEY_UNITS // r)
    out.flags.writeable = False
    return out


def brick_keys_of(cell, r: int) -> np.ndarray:
    """((r + 1)^3, 3) int: the probes of cell ``cell``'s brick of ``r``, in KEY_UNITS of a cell from the first node,
    in the brick's order lx + (r + 1) (ly + (r + 1) lz)."""
    return np.asarray(cell, int) * KEY_UNITS + _brick_offsets(int(r))


KEY_SPAN = 1 << 20  # a key's coordinates, offset by half of it, in [0, KEY_SPAN): one int64 a place (key_codes)


def key_codes(keys: np.ndarray) -> np.ndarray:
    """(M,) int64 for (M, 3) keys: equal keys, equal codes, and codes sort as the key tuples do (x, then y, then z),
    so sets of places are numpy arrays, not Python sets of tuples."""
    k = np.asarray(keys, np.int64).reshape(-1, 3) + KEY_SPAN // 2
    return (k[:, 0] * KEY_SPAN + k[:, 1]) * KEY_SPAN + k[:, 2]


def code_keys(codes: np.ndarray) -> np.ndarray:
    """key_codes' inverse: (M, 3) int keys."""
    c = np.asarray(codes, np.int64)
    return np.stack([c // KEY_SPAN ** 2, c // KEY_SPAN % KEY_SPAN, c % KEY_SPAN], -1) - KEY_SPAN // 2


def find_codes(table: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """(M,) the index in ``table`` of each of ``codes`` (each must be there), the last one where a code repeats (as
    a dict filled in table order keeps the last)."""
    order = np.argsort(table, kind="stable")
    at = np.searchsorted(table[order], codes, side="right") - 1
    if len(codes) and (np.any(at < 0) or np.any(table[order[np.maximum(at, 0)]] != codes)):
        raise KeyError("a place not in the table")
    return order[at]


def node_keys(spec: GridSpec) -> np.ndarray:
    """(N, 3) int: the grid's nodes in brick keys' units, in linear order."""
    return index_grid(spec.shape) * KEY_UNITS


def brick_keys(spec: GridSpec, refine: np.ndarray) -> np.ndarray:
    """(B, 3) int: every brick probe's place (brick_keys_of), bricks in cell order (the atlas's order): equal keys
    are one place (a brick's corners are grid nodes, neighbours share faces)."""
    r = np.asarray(refine, int)
    cells = index_grid(r.shape)
    out = [brick_keys_of(c, rc) for c, rc in zip(cells, flat_cells(r)) if rc > 1]
    return np.concatenate(out) if out else np.zeros((0, 3), int)


def key_positions(spec: GridSpec, keys: np.ndarray) -> np.ndarray:
    """(M, 3) world positions of brick_keys' keys."""
    first, step = node_frame(spec)
    return first + np.asarray(keys, np.float64) / KEY_UNITS * step


def pack_cells(volume: LightVolume) -> np.ndarray:
    """The node group's third image: one texel a cell (cell c at column c % cols, row c // cols, cols =
    ceil(sqrt(cells)), rows bottom first) of (its brick's first probe among the bricks', r, 0); float32 (whole
    numbers, exact)."""
    r = volume.cells
    vals = np.stack([flat_cells(brick_bases(r)), flat_cells(r), np.zeros(r.size)], -1).astype(np.float32)
    cols, rows = atlas_tiles(len(vals))
    img = np.zeros((rows * cols, 3), np.float32)
    img[:len(vals)] = vals
    return img.reshape(rows, cols, 3)


def _untile(atlas: np.ndarray, n: int, count: int, channels: int) -> np.ndarray:
    """_tile's inverse: the first ``count`` maps (count, n, n, channels) of an atlas of bordered n x n tiles."""
    t = n + 2
    cols, rows = atlas_tiles(count)
    a = np.asarray(atlas, np.float32)[:rows * t, :cols * t, :channels]
    tiles = a.reshape(rows, t, cols, t, channels).transpose(0, 2, 1, 3, 4).reshape(rows * cols, t, t, channels)
    return tiles[:count, 1:-1, 1:-1]


def unpack_volume(irr_atlas: np.ndarray, vis_atlas: np.ndarray, cells: np.ndarray, spec: GridSpec,
                  tiles: int) -> LightVolume:
    """The LightVolume that pack_atlas and pack_cells wrote these three images of (``tiles`` maps on ``spec``):
    what a saved file holds of its volume, so that a growth after reopening it starts from it (float32 maps)."""
    ncx, ncy, ncz = cell_shape(spec)
    r = np.asarray(cells, np.float32).reshape(-1, 3)[:ncx * ncy * ncz, 1].astype(int)
    refine = r.reshape(ncz, ncy, ncx).transpose(2, 1, 0)
    n, in_bricks = spec.count, int(sum((int(x) + 1) ** 3 for x in r if x > 1))
    if tiles != n + in_bricks:
        raise ValueError(f"the volume's images say {tiles} maps, not its {n} grid nodes and {in_bricks} brick probes")
    irr, mom = _untile(irr_atlas, IRR, tiles, 3), _untile(vis_atlas, VIS, tiles, 2)
    if not in_bricks:
        return LightVolume(spec, grid_maps(irr, spec.shape), grid_maps(mom, spec.shape))
    return LightVolume(spec, grid_maps(irr[:n], spec.shape), grid_maps(mom[:n], spec.shape), refine=refine,
                       brick_irradiance=irr[n:], brick_moments=mom[n:])


# ------------------------------------------------------------------------------------------------------------------
# Lookup

def _node_steps(spec: GridSpec) -> list[float]:
    """The node spacing of each axis with more than one node."""
    lo, hi, n = np.asarray(spec.lo), np.asarray(spec.hi), np.asarray(spec.shape)
    return [float((hi[a] - lo[a]) / (n[a] - 1)) for a in range(3) if n[a] > 1 and hi[a] > lo[a]]


def spec_spacing(spec: GridSpec) -> float:
    """The smallest node spacing over the axes with more than one node (the box's largest side, at least 1 m, with
    none)."""
    steps = _node_steps(spec)
    return min(steps) if steps else float(max(np.max(np.subtract(spec.hi, spec.lo)), 1.0))


def spacing_words(spec: GridSpec) -> str:
    """"0.26-0.33 m apart": the node spacings over the axes with more than one node (each axis rounds its node count
    up, so they differ), as the reports say it."""
    steps = _node_steps(spec)
    low, high = (min(steps), max(steps)) if steps else (spec_spacing(spec),) * 2
    return f"{low:.2f} m apart" if f"{low:.2f}" == f"{high:.2f}" else f"{low:.2f}-{high:.2f} m apart"


def shader_constants(spec: GridSpec, tiles: int | None = None) -> dict:
    """Every number the node group needs beside the three images, by name; ``tiles``: the atlases' maps
    (LightVolume.tiles; None: the grid's alone)."""
    cols, rows = atlas_tiles(spec.count if tiles is None else int(tiles))
    ccols, crows = atlas_tiles(int(np.prod(cell_shape(spec))))
    first, step = node_frame(spec)  # one node on an axis: the box's middle, step 0
    spacing = spec_spacing(spec)
    return {"lo": tuple(map(float, spec.lo)), "hi": tuple(map(float, spec.hi)), "shape": tuple(spec.shape),
            "cols": cols, "rows": rows, "irr": IRR, "vis": VIS,
            "irradiance_size": (cols * (IRR + 2), rows * (IRR + 2)),  # (width, height)
            "visibility_size": (cols * (VIS + 2), rows * (VIS + 2)),
            "cells": cell_shape(spec), "cells_size": (ccols, crows), "grid_count": spec.count,
            "first_node": tuple(map(float, first)), "node_step": tuple(map(float, step)),
            "normal_bias": NORMAL_BIAS * spacing, "spacing": spacing,
            "variance_floor": VARIANCE_FLOOR, "min_weight": MIN_WEIGHT, "crush": CRUSH}


CellAt = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def corners(spec: GridSpec, positions: np.ndarray, normals: np.ndarray, cell_at: CellAt) -> Iterator[tuple]:
    """Yields (probe index among LightVolume.all_maps (M,), trilinear (M,), probe position q (M, 3), P' (M, 3), unit
    normals) for the 8 corners of each point. ``cell_at(c)``: (M, 3) cell indices -> (brick base (M,), r (M,)), the
    cells image's texel (the module docstring's lookup)."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)
    p = np.asarray(positions, np.float64).reshape(-1, 3) + NORMAL_BIAS * spec_spacing(spec) * n
    shape = np.asarray(spec.shape)
    first, step = node_frame(spec)
    g = spec.grid_coords(p)
    c = np.minimum(np.floor(g), np.maximum(shape - 2, 0))
    base, r = (np.asarray(x, np.float64) for x in cell_at(c.astype(int)))
    local = (g - c) * r[:, None]
    l0 = np.minimum(np.floor(local), r[:, None] - 1)
    f = local - l0
    fine = r > 1
    for k in range(8):
        bits = np.array([(k >> a) & 1 for a in range(3)], float)
        corner = l0 + bits
        tri = np.prod(np.where(bits > 0, f, 1.0 - f), -1)
        node = np.minimum(c + corner, shape - 1)
        coarse = node[:, 0] + shape[0] * (node[:, 1] + shape[1] * node[:, 2])
        side = (r + 1)[:, None]
        brick = spec.count + base + corner[:, 0] + side[:, 0] * (corner[:, 1] + side[:, 0] * corner[:, 2])
        q = first + (c + corner / r[:, None]) * step
        yield np.where(fine, brick, coarse).astype(int), tri, q, p, n


def cells_of(volume: LightVolume) -> CellAt:
    """cell_at for ``volume``'s own cells (corners' argument)."""
    bases, r = brick_bases(volume.cells), volume.cells
    return lambda c: (bases[c[:, 0], c[:, 1], c[:, 2]], r[c[:, 0], c[:, 1], c[:, 2]])


def _cells_image(cells: np.ndarray | None, spec: GridSpec):
    """cell_at reading pack_cells' image texel by texel, as the node group does (None: no bricks)."""
    if cells is None:
        return lambda c: (np.zeros(len(c)), np.ones(len(c)))
    ncx, ncy, _ = cell_shape(spec)
    cols = cells.shape[1]

    def at(c):
        i = c[:, 0] + ncx * (c[:, 1] + ncy * c[:, 2])
        t = cells[i // cols, i % cols]
        return t[:, 0], t[:, 1]
    return at


def lookup_weight(q: np.ndarray, p: np.ndarray, moments: np.ndarray | None, tri: np.ndarray) -> np.ndarray:
    """One corner's weight (the module docstring's formula); ``moments`` (M, 2) at P' - q, None: no visibility."""
    w = np.ones(len(p))
    if moments is not None:
        r = np.linalg.norm(p - q, axis=-1)
        m, m2 = moments[:, 0], moments[:, 1]
        var = np.maximum(m2 - m * m, (VARIANCE_FLOOR * m) ** 2)
        w = np.where(r <= m, 1.0, (var / np.maximum(var + (r - m) ** 2, 1e-30)) ** 3)
    w = np.maximum(w, MIN_WEIGHT)
    w = np.where(w < CRUSH, w ** 3 / CRUSH ** 2, w)
    return w * tri


def away(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Directions probe -> point (+Z where they coincide: any direction serves, its distance is 0)."""
    d = p - q
    return np.where(np.linalg.norm(d, axis=-1, keepdims=True) > 0, d, [0.0, 0.0, 1.0])


def sample(volume: LightVolume, positions: np.ndarray, normals: np.ndarray, visibility: bool = True) -> np.ndarray:
    """E/pi (M, 3) at (M, 3) positions with (M, 3) normals, from the unpacked maps (sample_packed's reference)."""
    irr, mom = volume.all_maps()
    num, den = 0.0, 0.0
    for i, tri, q, p, n in corners(volume.spec, positions, normals, cells_of(volume)):
        vis = bilinear_map(mom, away(p, q), i) if visibility else None
        w = lookup_weight(q, p, vis, tri)
        num = num + w[:, None] * bilinear_map(irr, n, i)
        den = den + w
    return num / den[:, None]


def _atlas_lookup(atlas: np.ndarray, size: int, probe: np.ndarray, d: np.ndarray) -> np.ndarray:
    h, w = atlas.shape[:2]
    t = size + 2
    cols = w // t
    uv = oct_encode(d) * 0.5 + 0.5
    px = (probe % cols) * t + 1 + uv[:, 0] * size
    py = (probe // cols) * t + 1 + uv[:, 1] * size
    return _bilinear(atlas, px / w, py / h)


def sample_packed(irr_atlas: np.ndarray, vis_atlas: np.ndarray, spec: GridSpec, positions: np.ndarray,
                  normals: np.ndarray, visibility: bool = True, cells: np.ndarray | None = None) -> np.ndarray:
    """What the node group does with the three images: E/pi (M, 3) at (M, 3) positions with (M, 3) normals
    (``cells``: pack_cells' image; None: a volume without bricks)."""
    num, den = 0.0, 0.0
    for i, tri, q, p, n in corners(spec, positions, normals, _cells_image(cells, spec)):
        vis = _atlas_lookup(vis_atlas, VIS, i, away(p, q))[:, :2] if visibility else None
        w = lookup_weight(q, p, vis, tri)
        num = num + w[:, None] * _atlas_lookup(irr_atlas, IRR, i, n)
        den = den + w
    return num / den[:, None]


# ------------------------------------------------------------------------------------------------------------------
# Analytic test data

def default_field(p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """synthetic_volume's E/pi: a ramp in x and a sky in direction, (0.5 + 0.1 x, 0.4 + 0.3 n_z, 0.3 + 0.2 n_x)."""
    return np.stack([0.5 + 0.1 * p[..., 0], 0.4 + 0.3 * n[..., 2], 0.3 + 0.2 * n[..., 0]], -1)


def _field_maps(points: np.ndarray, irradiance_fn, wall_x: float | None, far: float):
    """(M, IRR, IRR, 3) and (M, VIS, VIS, 2) maps of synthetic_volume's fields at (M, 3) probe positions."""
    pts = points[:, None, None, :]
    irr = irradiance_fn(np.broadcast_to(pts, (len(points), IRR, IRR, 3)),
                        np.broadcast_to(texel_directions(IRR), (len(points), IRR, IRR, 3)))
    d = np.broadcast_to(texel_directions(VIS), (len(points), VIS, VIS, 3))
    r = np.full(d.shape[:-1], float(far))
    if wall_x is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (wall_x - points[:, None, None, 0]) / d[..., 0]
        r = np.where((t > 0) & np.isfinite(t), np.minimum(t, far), r)
    return np.asarray(irr, np.float64), np.stack([r, r * r], -1)


def synthetic_volume(spec: GridSpec, irradiance_fn=default_field, wall_x: float | None = None,
                     far: float = 100.0, refine: np.ndarray | None = None) -> LightVolume:
    """A volume of known maps, for tests of the lookup and of the node group (no render).

    ``irradiance_fn(positions (..., 3), normals (..., 3)) -> (..., 3)`` E/pi, sampled at each probe's texel centres
    (default_field). Moments: the distance (variance 0) to the plane x = ``wall_x`` along each texel's direction
    where the direction meets it, else ``far`` (wall_x None: no wall). ``refine``: each cell's r (bricks), their
    probes' maps from the same fields."""
    irr, mom = _field_maps(probe_positions(spec), irradiance_fn, wall_x, far)
    v = LightVolume(spec, grid_maps(irr, spec.shape), grid_maps(mom, spec.shape))
    if refine is not None and np.any(np.asarray(refine) > 1):
        v.refine = np.asarray(refine, int)
        v.brick_irradiance, v.brick_moments = _field_maps(key_positions(spec, brick_keys(spec, v.refine)),
                                                          irradiance_fn, wall_x, far)
    return v
