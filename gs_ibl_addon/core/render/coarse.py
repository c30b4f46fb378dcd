"""A coarse copy of a scene for drawing while the view moves: at most ``budget`` splats, merged over a uniform grid.

The octree level of detail (render/lod.py) picks a cut per view, but gs_preprocess still visits every node of the
tree to make that choice: on lavapipe that floor alone is about 0.2 s a frame at 3M splats, the whole frame budget
of an orbit at 5 frames/s. A scene whose size is fixed, whatever the original's, costs the same every frame instead.

Grid. One cell size h over the scene's robust bounds (lod.py's: the 0.05/99.95 percentiles; splats outside them are
kept as they are); h is searched so that the occupied cells number at most ``budget`` (and close to it: cells are
not restricted to powers of two, so a volume of splats does not jump 8x in count between choices). Each cell
holding two or more splats becomes one splat by lod.py's moment matching (weight = opacity x mean footprint;
weighted mean, second moment and SH; the random-medium opacity), which keeps a cell's coverage, so surfaces stay
closed where a random subset of the same size would turn see-through. A cell holding one splat keeps it unchanged.

Built in numpy with no GPU work, so it can run on a worker thread: on this 2-core machine, idle, 1.1 s at 1M splats
and 4.1 s at 3M (DC-only, as the overlay's host copy is; 2.3 and 5.9 s before lod.py's moments were made lean,
2026-12-03; docs/benchmarks.md, "Overlay while the view moves").
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..scene import SplatScene
from .lod import _grid, _moments_of_splats, _splats_of

DEFAULT_BUDGET = 100_000  # splats: the overlay's MOTION_BUDGET
_BITS = 21  # grid coordinates per axis packed in one int64 key
_SEARCH_STEPS = 6


@dataclass
class CoarseScene:
    scene: SplatScene  # what is drawn while moving (the original itself when it is within the budget)
    source_count: int
    cell: float  # grid cell size, 0 when nothing was merged
    merged: int  # splats of ``scene`` that stand for two or more of the original
    build_s: float


def _keys(cells: np.ndarray) -> np.ndarray:
    return (cells[:, 0] << (2 * _BITS)) | (cells[:, 1] << _BITS) | cells[:, 2]


def _occupied(rel: np.ndarray, h: float) -> int:
    return len(np.unique(_keys(np.floor(rel / h).astype(np.int64))))


def coarse_scene(scene: SplatScene, budget: int = DEFAULT_BUDGET) -> CoarseScene:
    """At most ``budget`` splats that look like ``scene`` from any view at a coarse resolution (see the module)."""
    t0 = time.perf_counter()
    n = scene.count
    if budget < 1:
        raise ValueError(f"coarse scene budget {budget} must be at least 1 splat")
    if n <= budget:
        return CoarseScene(scene, n, 0.0, 0, time.perf_counter() - t0)
    origin, cell1, bits = _grid(scene)
    extent = cell1 * 2 ** bits
    pos = scene.positions.astype(np.float64)
    inside = np.all((pos >= origin) & (pos < origin + extent), 1)
    outside = int(n - inside.sum())
    rel = pos[inside] - origin
    room = budget - outside
    if room < 1:  # nearly every splat is an outlier: nothing sensible to merge, draw a plain subset instead
        keep = np.sort(np.random.default_rng(0).choice(n, budget, replace=False))
        return CoarseScene(_take(scene, keep), n, 0.0, 0, time.perf_counter() - t0)
    # Occupied cells fall as h grows, roughly as h^-d with d between 2 (surfaces) and 3 (volumes): a secant search
    # in log-log space, keeping the smallest h found whose count fits.
    lo_h = extent / 2 ** _BITS  # finest grid the keys hold
    h = max(lo_h, extent / room ** (1.0 / 2.5))  # between a surface's and a volume's count
    best = None
    prev = None
    for _ in range(_SEARCH_STEPS):
        c = _occupied(rel, h)
        if c <= room and (best is None or h < best[0]):
            best = (h, c)
        if 0.85 * room <= c <= room:
            break
        if prev is not None and prev[1] != c and prev[0] != h:
            slope = (np.log(c) - np.log(prev[1])) / (np.log(h) - np.log(prev[0]))
            slope = float(np.clip(slope, -3.5, -1.0))
        else:
            slope = -2.5
        prev = (h, c)
        h = max(lo_h, h * float(np.exp((np.log(0.95 * room) - np.log(c)) / slope)))
    if best is None:  # the search ended above the budget: double until it fits
        while True:
            h *= 2.0
            c = _occupied(rel, h)
            if c <= room:
                best = (h, c)
                break
    h = best[0]
    idx_inside = np.flatnonzero(inside)
    keys = _keys(np.floor(rel / h).astype(np.int64))
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    single = counts[inverse] == 1
    multi_cells = np.flatnonzero(counts >= 2)
    remap = np.full(len(counts), -1, np.int64)
    remap[multi_cells] = np.arange(len(multi_cells))
    sel = np.zeros(n, bool)
    sel[idx_inside[~single]] = True
    mom, _ = _moments_of_splats(scene, sel)  # rows in storage order of the selected splats
    merged = mom.merged(remap[inverse[~single]], len(multi_cells))
    mu, s, q, o, sh = _splats_of(merged, scene.sh.shape[1], scene.colour_space == "srgb")
    keep = np.sort(np.concatenate([np.flatnonzero(~inside), idx_inside[single]]))
    kept = _take(scene, keep)
    f32 = np.float32
    out = SplatScene(np.concatenate([kept.positions, mu.astype(f32)]), np.concatenate([kept.scales, s.astype(f32)]),
                     np.concatenate([kept.rotations, q.astype(f32)]), np.concatenate([kept.opacities, o.astype(f32)]),
                     np.concatenate([kept.sh, sh.astype(f32)]), source=f"{scene.source} (coarse, {budget:,})",
                     colour_space=scene.colour_space)
    return CoarseScene(out, n, float(h), len(multi_cells), time.perf_counter() - t0)


def _take(scene: SplatScene, idx: np.ndarray) -> SplatScene:
    return SplatScene(scene.positions[idx], scene.scales[idx], scene.rotations[idx], scene.opacities[idx],
                      scene.sh[idx], source=scene.source, colour_space=scene.colour_space)
