"""Bricks where the light changes inside a cell: "model no more than a scene needs" (issue 37).

A regular grid follows the light only as well as its spacing: 512 probes over the sample room are 0.54 m apart,
and 0.5 m below its lamp the light changes 10% over 0.25 m, so a sphere there read +10..+47%. Finer everywhere
costs the whole room for a few cells. Here each cell is asked instead:

- Measure: the grid's nodes and every cell's centre are baked together (volume_bake.bake_probes). At a centre the
  lookup (volume.sample: eight corners, trilinear x Chebyshev) is compared with the centre's own map over
  ERROR_NORMALS directions: the mean absolute luminance error over the mean is the cell's error. The centre is where
  trilinear interpolation errs most for a smooth field, and it sees what the corners miss: a lamp or a wall inside
  the cell.
- Choose: linear interpolation errs as the square of the spacing, so a brick of r (volume.BRICK_LEVELS: 2 or 4;
  its nodes r + 1 a side, the centre one of them) cuts the error about r^2 times. The next level goes to the cell
  whose brick removes the most error per probe it adds (bricks share their faces and corners with the grid and each
  other: a probe is rendered once), while the cell is over the tolerance and the budget holds its probes. A 4x brick
  adds 98 probes to a 2x's 18, so it waits until the 2x bricks of other cells are worth less. Worst cell first gave
  the sample room's lamp cell a 4x brick while 13 cells kept none, and the window's sphere read +3.8%
  (auto_light_bench, 2026-12-06: 6 bricks, Cycles 7 / 10 within 3%, EEVEE 6 / 10); per probe: 14 bricks at 2x, 5
  cells left, every sphere within 3% in both engines, Cycles 8 / 10, EEVEE 7 / 10. Straight to the finest level
  had spent the budget on a few cells (2026-12-05: the window's sphere +5%).
- Bake: the new probes, in batched submissions; the bricks' maps are gathered from grid nodes, centres and new
  probes by place (volume.brick_keys).

A brick's face meets an unrefined neighbour's face at different nodes: the light is continuous only where both
agree, so the seam is at most the coarse cell's own interpolation error (what the brick was made for). Nested
levels keep r = 2 and r = 4 faces on shared nodes.
"""
from __future__ import annotations

import heapq
from typing import Callable

import numpy as np

from .grid import GridSpec
from .variation import LUMINANCE
from ..synthetic import fibonacci_sphere
from .volume import (BRICK_LEVELS, IRR, KEY_UNITS, NORMAL_BIAS, LightVolume, away, bilinear_map, bilinear_taps,
                     brick_keys, brick_keys_of, cell_shape, cells_of, code_keys, corners, find_codes, flat_cells,
                     flat_maps, grid_maps, index_grid, key_codes, key_positions, lookup_weight, node_frame, node_keys,
                     probe_positions, spec_spacing)
from .volume_bake import DEFAULT_FACE, bake_probes, far_distance, probe_report
from .volume_region import DEFAULT_BUDGET, MAX_NODES, VolumePlan, choose_volume, region_box

# The grid's share of the probe budget; the cells' centres and the bricks take the rest. Over the sample room's five
# places (volume_bench.py, 2026-12-05, 64 points a sphere): the grid at 0.6 m (300 probes) and bricks to 512 put
# every place's camera-facing mean within 3% (the grid alone: 3 of 5; at 1.0 m with 430 probes of bricks: 4 of 5,
# the lamp's 4.7% low), per point 1.3-3.3% mean (the grid alone 1.3-16%).
GRID_SHARE = 0.6
# A grown volume (extend_volume) may hold up to this many times the budget: a whole bake fills the budget (its grid
# coarsened to GRID_SHARE of it, bricks the rest), so a budget for the total would refuse every growth (the sample
# room, 2026-12-06: drags of 0.4-1.0 m all passed it), while each growth renders only what the move needs.
GROW_LIMIT = 2.0
REFINE_TOLERANCE = 0.02  # a cell's error at its centre (mean absolute luminance error over the mean) a brick is for
# Directions a centre's error is measured over: 64 read the sample room's 47 centres within 0.31% (absolute, median
# 0.07%) of the map's 289 texel directions at an eighth of the host time (numpy: 0.10 against 0.72 s on a loaded
# 2-core CPU, most of a bake's host time on a GPU).
ERROR_NORMALS = 64


def cell_keys(spec: GridSpec) -> np.ndarray:
    """(C, 3) every cell's centre in brick_keys' units, cells in linear order."""
    return index_grid(cell_shape(spec)) * KEY_UNITS + KEY_UNITS // 2


def cells_touching(spec: GridSpec, boxes) -> np.ndarray:
    """(C,) bool in cell order: cells whose box meets any of ``boxes`` ((lo, hi) pairs; None: every cell)."""
    keys = cell_keys(spec)
    if boxes is None:
        return np.ones(len(keys), bool)
    lo = key_positions(spec, keys - KEY_UNITS // 2)
    hi = key_positions(spec, keys + KEY_UNITS // 2)
    out = np.zeros(len(keys), bool)
    for blo, bhi in boxes:
        out |= np.all(lo <= np.asarray(bhi, np.float64) + 1e-9, 1) & np.all(hi >= np.asarray(blo, np.float64) - 1e-9,
                                                                            1)
    return out


def centre_errors(volume: LightVolume, centre_irradiance: np.ndarray, cells: np.ndarray | None = None) -> np.ndarray:
    """(C,) the error of each of ``cells`` ((C,) indices in cell order; None: all): the lookup at its centre against
    the centre's own map (C, IRR, IRR, 3), over ERROR_NORMALS directions, mean |luminance difference| / mean
    luminance.

    volume.sample at every (centre, normal) pair, taken apart: a lookup moves its point along the normal by the bias
    before it interpolates, so points started that far back all land on the centre, and their eight corners, corner
    weights and visibility are the centre's alone. Per centre: eight weights; per normal: the same four texels of
    every map (one set of bilinear taps), the eight corners of every centre in one pass. The same numbers as
    sampling each pair (tests/test_volume_refine.py) in a twelfth of the host time (the sample room's 47 centres:
    17 -> 1.4 ms on a 2-core CPU; it was most of a GPU bake's host time)."""
    spec = volume.spec
    keys = cell_keys(spec)
    centres = key_positions(spec, keys if cells is None else keys[cells])
    normals = fibonacci_sphere(ERROR_NORMALS)
    taps, tap_w = bilinear_taps(IRR, normals)  # (E, 4): the same for every map
    irr, mom = volume.all_maps()
    lum_maps = irr.reshape(len(irr), IRR * IRR, 3) @ LUMINANCE  # luminance is linear: taken before the lookups
    up = np.broadcast_to([0.0, 0.0, 1.0], centres.shape)
    # the eight corners of every centre at once, (8 C, ...): numpy's cost per call was most of the time
    i, tri, q, p, _n = (np.concatenate(x) for x in zip(*corners(spec, centres - NORMAL_BIAS * spec_spacing(spec) * up,
                                                               up, cells_of(volume))))
    w = lookup_weight(q, p, bilinear_map(mom, away(p, q), i), tri).reshape(8, -1)
    lum = (lum_maps[i][:, taps] * tap_w).sum(-1).reshape(8, len(centres), -1)
    got = np.einsum("jc,jce->ce", w, lum) / w.sum(0)[:, None]
    own = np.asarray(centre_irradiance, np.float64).reshape(len(centres), IRR * IRR, 3) @ LUMINANCE
    want = (own[:, taps] * tap_w).sum(-1)
    return np.abs(got - want).mean(1) / np.maximum(np.abs(want).mean(1), 1e-12)


def choose_bricks(spec: GridSpec, errors: np.ndarray, tolerance: float, budget: int) -> np.ndarray:
    """(cx, cy, cz) r per cell from (C,) ``errors`` in cell order (0: a cell not measured), within ``budget`` new
    probes (not grid nodes, centres or another brick's). The next level goes to the cell whose brick removes the most
    error per new probe (its error x (1 - (r / next)^2) over the probes it adds), while the cell is over ``tolerance``
    and its probes fit; a brick that does not fit is passed over for smaller ones."""
    shape = cell_shape(spec)
    refine = np.ones(shape, int)
    if min(spec.shape) < 2 or budget <= 0:
        return refine
    taken = set(key_codes(np.vstack([node_keys(spec), cell_keys(spec)])).tolist())
    cells = index_grid(shape)

    def worth(i: int, r: int, e: float) -> tuple[float, int, set] | None:
        """(error removed per new probe, next level, its new probes) of cell i's next brick, or None."""
        nxt = next((x for x in BRICK_LEVELS if x > r), None)
        if nxt is None:
            return None
        new = set(key_codes(brick_keys_of(cells[i], nxt)).tolist()) - taken
        return e * (1 - (r / nxt) ** 2) / max(len(new), 1), nxt, new
    queue = []
    for i, e in enumerate(errors):
        w = worth(i, 1, float(e)) if e > tolerance else None
        if w is not None:
            queue.append((-w[0], i, 1, float(e)))
    heapq.heapify(queue)
    added = 0
    while queue:
        neg, i, r, e = heapq.heappop(queue)
        w = worth(i, r, e)
        if w is None:
            continue
        if queue and w[0] < -queue[0][0] - 1e-15:  # its new probes shrank or grew since: queued again as it is now
            heapq.heappush(queue, (-w[0], i, r, e))
            continue
        _, nxt, new = w
        if added + len(new) > budget:
            continue
        refine[tuple(cells[i])] = nxt
        taken |= new
        added += len(new)
        left = e * (r / nxt) ** 2
        w = worth(i, nxt, left) if left > tolerance else None
        if w is not None:
            heapq.heappush(queue, (-w[0], i, nxt, left))
    return refine


def bake_refined(renderer, spec: GridSpec, budget: int, tolerance: float = REFINE_TOLERANCE, boxes=None,
                 face_size: int = DEFAULT_FACE, progress: Callable[[int, int], None] | None = None,
                 hole_colour=(0.0, 0.0, 0.0), lod_k: float = 0.0) -> LightVolume:
    """The light volume on ``spec`` with bricks where its cells' centres say the grid misses the light, in the cells
    that meet ``boxes`` (the lit meshes' boxes, over an animation; None: every cell): at most ``budget`` probes
    rendered in all (grid, centres, bricks; the grid and centres always). Timings as bake_volume's, plus the probe
    counts; the report says what was refined."""
    far, near = far_distance(spec), 0.5 * spec_spacing(spec)
    cells = np.flatnonzero(cells_touching(spec, boxes)) if min(spec.shape) >= 2 else np.zeros(0, int)
    n, centre_keys = spec.count, cell_keys(spec)[cells]
    centres = key_positions(spec, centre_keys)
    first = bake_probes(renderer, np.vstack([probe_positions(spec), centres]), far, near, face_size,
                        None if progress is None else lambda d, t: progress(d, t + max(budget - t, 0)),
                        hole_colour, True, lod_k)
    grid = LightVolume(spec, grid_maps(first["irradiance"][:n], spec.shape), grid_maps(first["moments"][:n],
                                                                                      spec.shape))
    errors = np.zeros(int(np.prod(cell_shape(spec))))
    errors[cells] = np.where(first["inside"][n:], 0.0,  # a centre inside an object: no mesh stands there
                             centre_errors(grid, first["irradiance"][n:], cells))
    refine = choose_bricks(spec, errors, tolerance, budget - len(first["holes"]))
    codes = key_codes(brick_keys(spec, refine))
    known = key_codes(np.vstack([node_keys(spec), centre_keys]))  # first's probes, in its order
    new = np.setdiff1d(codes, known)  # sorted: the same order whatever the bricks' order
    done = len(first["holes"])
    second = bake_probes(renderer, key_positions(spec, code_keys(new)), far, near, face_size,
                         None if progress is None else lambda d, t: progress(done + d, done + t),
                         hole_colour, True, lod_k) if len(new) else None
    irr, mom = first["irradiance"], first["moments"]
    holes, inside = first["holes"], first["inside"]
    if second is not None:
        irr, mom = np.concatenate([irr, second["irradiance"]]), np.concatenate([mom, second["moments"]])
        holes, inside = np.concatenate([holes, second["holes"]]), np.concatenate([inside, second["inside"]])
    at = find_codes(np.concatenate([known, new]), codes)
    vol = LightVolume(spec, grid.irradiance, grid.moments, refine=refine if len(codes) else None,
                      brick_irradiance=irr[at] if len(codes) else None, brick_moments=mom[at] if len(codes) else None)
    levels = {r: int((refine == r).sum()) for r in BRICK_LEVELS if (refine == r).any()}
    worst = float(errors.max()) if len(errors) else 0.0
    if levels:
        report = [f"bricks in {sum(levels.values())} of {refine.size} cells (" + ", ".join(
            f"{c} at {r}x" for r, c in levels.items()) + f"), {len(new)} probes more: the light changed up to "
            f"{100 * worst:.0f}% inside a cell"]
    elif min(spec.shape) < 2:
        report = ["no bricks: the volume is one node thick on an axis"]
    elif worst <= tolerance:
        report = [f"no bricks: the light inside every cell is within {100 * tolerance:.0f}% of the grid's"]
    else:
        report = []
    over = int(((errors > tolerance) & (flat_cells(refine) == 1)).sum())
    if over and min(spec.shape) >= 2:
        report.append(f"{over} cells over the {100 * tolerance:.0f}% tolerance kept no brick: over the probe budget "
                      f"of {budget}")
    vol.report = report + probe_report(holes, inside, hole_colour)
    rs = [first] + ([second] if second is not None else [])
    vol.timings = {"render": sum(b["render_ms"] for b in rs), "maps": sum(b["maps_ms"] for b in rs),
                   "probes": len(holes), "grid": n, "centres": len(centres), "bricks": len(new),
                   "face": int(face_size), "per_submission": first["per_submission"], "lod_k": float(lod_k),
                   "cell_error_max": worst}
    return vol


def bake_light_volume(renderer, boxes, budget: int = DEFAULT_BUDGET, within=None, face_size: int = DEFAULT_FACE,
                      progress: Callable[[int, int], None] | None = None) -> tuple[VolumePlan, LightVolume]:
    """Lighting Volume's bake for the lit meshes' ``boxes`` (over an animation): the region planned from the light
    it measures (volume_region.choose_volume, the grid within GRID_SHARE of ``budget``), then the volume with its
    bricks (bake_refined). ``within``: a box the region stays inside (the splats' bounds)."""
    plan, _coarse = choose_volume(renderer, boxes, budget=budget, within=within, share=GRID_SHARE)
    return plan, bake_refined(renderer, plan.spec, budget, boxes=boxes, face_size=face_size, progress=progress)


def grown_spec(spec: GridSpec, boxes, within=None, thin_ok: bool = False) -> tuple[GridSpec, np.ndarray] | None:
    """``spec`` grown on its own lattice (same first node, same steps) until it holds ``boxes`` (cut to
    ``within``): (the grown spec, (3,) nodes added below on each axis), or None when nothing is outside it or it
    cannot grow along an axis it must (one node there; ``thin_ok``: then ``spec`` itself and its nodes below)."""
    first, step = node_frame(spec)
    n = np.asarray(spec.shape, int)
    last = first + (n - 1) * step
    lo, hi = region_box(boxes, 0.0, within)
    below = np.where(step > 0, np.ceil((first - lo) / np.where(step > 0, step, 1.0) - 1e-9), 0).astype(int)
    above = np.where(step > 0, np.ceil((hi - last) / np.where(step > 0, step, 1.0) - 1e-9), 0).astype(int)
    below, above = np.maximum(below, 0), np.maximum(above, 0)
    thin = (step == 0) & ((lo < first - 1e-9) | (hi > last + 1e-9))
    if thin.any():
        return (spec, below) if thin_ok else None
    if not (below.any() or above.any()):
        return None
    shape = tuple(int(x) for x in n + below + above)
    return GridSpec(tuple(map(float, first - below * step)), tuple(map(float, last + above * step)), shape), below


def extend_volume(renderer, previous: LightVolume, boxes, budget: int = DEFAULT_BUDGET,
                  tolerance: float = REFINE_TOLERANCE, within=None, face_size: int = DEFAULT_FACE,
                  progress: Callable[[int, int], None] | None = None, hole_colour=(0.0, 0.0, 0.0),
                  lod_k: float = 0.0) -> LightVolume | None:
    """``previous`` grown over ``boxes`` (the lit meshes' boxes now, over an animation) on its own lattice, with only
    what changed rendered: the new nodes, the centres of the new cells the boxes touch and those cells' bricks; every
    node and brick it had keeps its maps (rendered with its ``far`` and ``near``, so a grown volume's old part is the
    old volume); ``previous`` itself when the boxes lie inside it (nothing to render); None when it cannot grow on
    its lattice (one node thick along an axis it must grow), when what it renders would pass ``budget`` (the most a
    bake renders), or when the grown volume would hold more than GROW_LIMIT x ``budget`` probes or MAX_NODES a side:
    then bake anew (bake_light_volume), at the spacing the new region's light asks for."""
    old = previous.spec
    grown = grown_spec(old, boxes, within, thin_ok=True)
    if grown is None:
        return previous
    spec, below = grown
    if spec is old:  # it must grow along an axis of one node
        return None
    far, near = far_distance(old), 0.5 * spec_spacing(old)
    n_old = np.asarray(old.shape)
    old_cells = np.asarray(cell_shape(old))
    nodes = index_grid(spec.shape)
    is_old_node = np.all((nodes >= below) & (nodes < below + n_old), 1)
    cells = index_grid(cell_shape(spec))
    is_old_cell = np.all((cells >= below) & (cells < below + old_cells), 1)
    fresh_cells = np.flatnonzero(~is_old_cell & cells_touching(spec, boxes))
    centre_keys = cell_keys(spec)[fresh_cells]
    old_bricks = previous.brick_count
    new_nodes = np.flatnonzero(~is_old_node)
    first_count = len(new_nodes) + len(fresh_cells)
    if (max(spec.shape) > MAX_NODES or first_count > budget or spec.count + old_bricks > GROW_LIMIT * budget
            or min(old.shape) < 2):
        return None
    first = bake_probes(renderer, np.vstack([probe_positions(spec)[new_nodes], key_positions(spec, centre_keys)]),
                        far, near, face_size, progress, hole_colour, True, lod_k)
    irr = np.empty((spec.count, *previous.irradiance.shape[3:]))
    mom = np.empty((spec.count, *previous.moments.shape[3:]))
    old_index = nodes[is_old_node] - below  # the old node each kept node is, in the new grid's linear order
    flat_old = old_index[:, 0] + n_old[0] * (old_index[:, 1] + n_old[1] * old_index[:, 2])
    irr[is_old_node], mom[is_old_node] = flat_maps(previous.irradiance)[flat_old], flat_maps(previous.moments)[
        flat_old]
    k = len(new_nodes)
    irr[new_nodes], mom[new_nodes] = first["irradiance"][:k], first["moments"][:k]
    grid = LightVolume(spec, grid_maps(irr, spec.shape), grid_maps(mom, spec.shape))
    errors = np.zeros(len(cells))
    errors[fresh_cells] = np.where(first["inside"][k:], 0.0, centre_errors(grid, first["irradiance"][k:], fresh_cells))
    refine = choose_bricks(spec, errors, tolerance, budget - first_count)
    shift = below * KEY_UNITS
    old_refine = previous.cells
    sl = tuple(slice(int(b), int(b) + int(c)) for b, c in zip(below, old_cells))
    refine[sl] = old_refine  # the old cells keep their bricks (their errors were 0 here: none chosen)
    keys = brick_keys(spec, refine)
    codes = key_codes(keys)
    # every place a brick may take its maps from, in this order (a later one wins a place: an old brick's corner is
    # a grid node too, with the same maps): the grid, the new centres, the old bricks, the new bricks' probes
    table = [key_codes(node_keys(spec)), key_codes(centre_keys)]
    maps = [(irr, mom), (first["irradiance"][k:], first["moments"][k:])]
    if old_bricks:
        table.append(key_codes(brick_keys(old, old_refine) + shift))
        maps.append((previous.brick_irradiance, previous.brick_moments))
    new = np.setdiff1d(codes, np.concatenate(table))
    second = bake_probes(renderer, key_positions(spec, code_keys(new)), far, near, face_size,
                         None, hole_colour, True, lod_k) if len(new) else None
    if second is not None:
        table.append(new)
        maps.append((second["irradiance"], second["moments"]))
    at = find_codes(np.concatenate(table), codes)
    b_irr = np.concatenate([m[0] for m in maps])[at] if len(keys) else None
    b_mom = np.concatenate([m[1] for m in maps])[at] if len(keys) else None
    vol = LightVolume(spec, grid.irradiance, grid.moments, refine=refine if len(keys) else None,
                      brick_irradiance=b_irr, brick_moments=b_mom)
    rs = [first] + ([second] if second is not None else [])
    holes, inside = np.concatenate([b["holes"] for b in rs]), np.concatenate([b["inside"] for b in rs])
    rendered = len(holes)
    added = int((refine > 1).sum()) - int((old_refine > 1).sum())
    bricks = f", {len(new)} for {added} new brick{'s' if added != 1 else ''}" if added > 0 else ""
    vol.report = [f"light volume grown to a grid of {' x '.join(map(str, spec.shape))} probes over what the meshes "
                  f"reach now: {rendered} probes rendered ({k} new grid probes, {len(fresh_cells)} cell centres"
                  f"{bricks}), {spec.count - k} grid probes and {old_bricks} brick probes kept"]
    vol.report += probe_report(holes, inside, hole_colour)
    vol.timings = {"render": sum(b["render_ms"] for b in rs), "maps": sum(b["maps_ms"] for b in rs), "probes": rendered,
                   "grid": spec.count, "kept": int(spec.count - k), "centres": len(fresh_cells), "bricks": len(new),
                   "face": int(face_size), "per_submission": first["per_submission"], "lod_k": float(lod_k)}
    return vol
