"""The light each mesh needs, chosen from probes around it: the World probe, a probe of its own, or a grid.

One probe lights every mesh as if it stood at the probe. Whether that is enough for a mesh is measured, not asked:
order-2 SH probes (MEASURE_FACE^2 faces) at the centre and the 8 corners of the mesh's box (shrunk towards its
centre: SHRINK), baked in the same batch as one at the World probe's place, give

    offset    = max_n |E_centre(n) - E_world(n)| / mean_n E_centre(n)   (the mesh stands elsewhere in the light)
    variation = max_corner max_n |E_corner(n) - E_centre(n)| / mean_n E_centre(n)   (the light changes across it)

(luminance, over 64 normals: the light a diffuse surface sees). Within the tolerance on both the World is enough;
else with a uniform light over the mesh its own probe at its centre (the centre's measurement); else a 3 x 3 x 3
grid over it, 5 x 5 x 5 where the light changes by more than its mean across it (a lamp close above: 0.5 m below the
sample room's lamp a Suzanne rendered +9% over native Cycles with 3 x 3 x 3, +1.3% with 5 x 5 x 5, 2026-12-03).
"Model no more than a scene needs": the measurement costs 9 small probes a mesh, and only the meshes whose light
varies across them get a grid baked (a second batch, of the 18 or 116 nodes the measurement did not place).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Generator

import numpy as np

from .grid import POINT_FACE_SIZE, GridSpec, bake_sh_points, eval_irradiance, interpolate, monomial_coefficients
from .variation import LUMINANCE, NORMALS

GRID_SHAPE = (3, 3, 3)
DENSE_SHAPE, DENSE_VARIATION = (5, 5, 5), 1.0  # light changing by more than its mean across a mesh (a lamp close by)
MEASURE_FACE = POINT_FACE_SIZE  # the measuring probes: the local-light operators' size (a mesh's own probe is its
# centre's measurement). Smaller reads render noise as light: a 10 cm sphere beside the World probe read 13% across
# it at 32^2, 3.4% at 64^2 against 2.7% at 256^2 (grid.py).
# The grid spans this fraction of the mesh's box about its centre: nodes a little inside the mesh's surface, so a mesh
# resting on a floor or a table keeps them off those splats, and the surface's light is interpolated, not held at the
# nearest face's. Mean light on a 0.25 m sphere's camera-facing surface, grid / probes at its surface points (numpy,
# the five places of benchmarks/auto_light_bench.py, 2026-12-03): 0.70 (clamped beyond 70%) -1.5..-4.4% on the table
# and +1.7..+2.1% by the window; 0.85 within 0.7% everywhere; 1.0 +3..+6% below the lamp (its light falls ~1/d^2
# between nodes); order-4 SH instead of order 2 changed none of these by more than 0.5%.
SHRINK = 0.85
MIN_SPAN = 0.05  # metres: a box thinner than this along an axis gets one node on it
KINDS = ("world", "probe", "grid")


def measure_points(lo, hi) -> np.ndarray:
    """(9, 3): the centre, then the 8 corners, of the mesh's shrunk box (the points its light is measured at)."""
    from .variation import box_points
    spec = mesh_grid(lo, hi)
    return box_points(spec.lo, spec.hi)


def mesh_grid(lo, hi, variation: float = 0.0) -> GridSpec:
    """The grid of probes that lights a mesh with box lo..hi whose light varies across it by ``variation``
    (choose_light's measure): DENSE_SHAPE where it exceeds DENSE_VARIATION."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * SHRINK
    full = DENSE_SHAPE if variation > DENSE_VARIATION else GRID_SHAPE
    shape = tuple(n if 2 * h >= MIN_SPAN else 1 for n, h in zip(full, half))
    return GridSpec(tuple(map(float, centre - half)), tuple(map(float, centre + half)), shape)


def measured_nodes(spec: GridSpec, measured: np.ndarray) -> np.ndarray:
    """For each node of ``spec`` (flattened as spec.points()), the index of the measure point at the same place,
    or -1: a mesh's grid holds its centre and box corners (measure_points of the same box), which need no second
    render (a probe rendered in another batch differs by ~1e-5 of its value)."""
    nodes = spec.points().reshape(-1, 3)
    d = np.linalg.norm(nodes[:, None, :] - np.asarray(measured, np.float64)[None], axis=2)
    return np.where(d.min(1) < 1e-9, d.argmin(1), -1)


def centre_index(spec: GridSpec) -> tuple[int, int, int]:
    return tuple(n // 2 for n in spec.shape)


@dataclass(frozen=True)
class LightChoice:
    name: str
    kind: str  # one of KINDS
    offset: float  # relative difference of the mesh centre's light from the World probe's
    variation: float  # relative change of the light across the mesh

    def message(self) -> str:
        o, v = 100 * self.offset, 100 * self.variation
        if self.kind == "world":
            return f"{self.name}: the World probe ({o:.0f}% off, {v:.0f}% across it)"
        if self.kind == "probe":
            return f"{self.name}: its own probe (the World's light is {o:.0f}% off; {v:.0f}% across it)"
        return f"{self.name}: a grid over it (light varies {v:.0f}% across it)"


def _luminance(d: np.ndarray) -> np.ndarray:
    """Monomial coefficients (..., 9, 3) -> irradiance luminance over NORMALS (..., 64)."""
    d = np.asarray(d, np.float64)
    return eval_irradiance(d[..., None, :, :], NORMALS) @ LUMINANCE


def choose_light(name: str, d_world: np.ndarray, d_points: np.ndarray, tolerance: float) -> LightChoice:
    """The light ``name`` needs: ``d_world`` (9, 3) the World probe's monomial coefficients, ``d_points`` (9, 9, 3)
    those at measure_points (centre first), baked alike."""
    e_nodes = _luminance(np.asarray(d_points)[1:])
    e_centre = _luminance(np.asarray(d_points)[0])
    e_world = _luminance(d_world)
    scale = max(float(np.mean(np.maximum(e_centre, 0.0))), 1e-9)
    offset = float(np.max(np.abs(e_centre - e_world)) / scale)
    variation = float(np.max(np.abs(e_nodes - e_centre[None])) / scale)
    kind = "grid" if variation > tolerance else "probe" if offset > tolerance else "world"
    return LightChoice(name, kind, offset, variation)


@dataclass(frozen=True)
class AutoLight:
    """Lighting Auto's light for a set of meshes: the World probe's monomial coefficients ``d_world`` (9, 3), each
    mesh's choice, its measure points (meshes, 9, 3) and their coefficients ``measured`` (meshes, 9, 9, 3), and for
    each mesh that got a grid {mesh index: (its grid, node coefficients (*grid shape, 9, 3))}."""
    d_world: np.ndarray
    choices: tuple[LightChoice, ...]
    points: np.ndarray
    measured: np.ndarray
    grids: dict[int, tuple[GridSpec, np.ndarray]]

    def coefficients_at(self, i: int, positions: np.ndarray) -> np.ndarray:
        """(M, 9, 3): the light mesh ``i`` is given at world ``positions`` (M, 3), as the local-light group reads it
        (the World's, its centre's, or its grid's interpolated)."""
        n, kind = len(positions), self.choices[i].kind
        if kind == "grid":
            spec, nodes = self.grids[i]
            return interpolate(nodes, spec, np.asarray(positions, np.float64))
        d = self.d_world if kind == "world" else self.measured[i, 0]
        return np.broadcast_to(d, (n, *d.shape))


def auto_light_batches(at, boxes, names, tolerance: float) -> Generator[np.ndarray, np.ndarray, AutoLight]:
    """Lighting Auto for meshes ``names`` with world boxes ``boxes`` (lo, hi) and the World probe at ``at``, as a
    generator that yields each batch's probe points (P, 3) and is sent their monomial coefficients (P, 9, 3), baked
    at MEASURE_FACE: the measurement (the World probe's place first, then each mesh's measure_points), then, when a
    mesh needs a grid, the grids' nodes the measurement did not place. A caller chooses where the batches run (the
    add-on's job runs them on a worker); auto_light runs them here."""
    points = np.asarray([measure_points(*box) for box in boxes], np.float64).reshape(len(boxes), 9, 3)
    both = yield np.vstack([np.asarray(at, np.float64)[None], points.reshape(-1, 3)])
    d_world = np.asarray(both[0])
    measured = np.asarray(both[1:]).reshape(len(boxes), 9, *d_world.shape)
    choices = tuple(choose_light(n, d_world, measured[i], tolerance) for i, n in enumerate(names))
    specs = {i: mesh_grid(*boxes[i], c.variation) for i, c in enumerate(choices) if c.kind == "grid"}
    reuse = {i: measured_nodes(spec, points[i]) for i, spec in specs.items()}
    fresh = {i: spec.points().reshape(-1, 3)[reuse[i] < 0] for i, spec in specs.items()}
    todo = np.concatenate([np.empty((0, 3)), *fresh.values()])
    dg = (yield todo) if len(todo) else np.empty((0, *d_world.shape))
    grids, start = {}, 0
    for i, spec in specs.items():
        m = reuse[i]
        nodes = np.empty((spec.count, *d_world.shape))
        nodes[m >= 0] = measured[i, m[m >= 0]]
        nodes[m < 0] = dg[start:start + len(fresh[i])]
        start += len(fresh[i])
        grids[i] = (spec, nodes.reshape(*spec.shape, *d_world.shape))
    return AutoLight(d_world, choices, points, measured, grids)


def run_batches(batches: Generator[np.ndarray, np.ndarray, AutoLight],
                bake: Callable[[np.ndarray], np.ndarray]) -> AutoLight:
    """Drive auto_light_batches with ``bake`` (points -> monomial coefficients) in this thread."""
    try:
        points = next(batches)
        while True:
            points = batches.send(bake(points))
    except StopIteration as done:
        return done.value


def measure_bake(renderer) -> Callable[[np.ndarray], np.ndarray]:
    """Points (P, 3) -> monomial coefficients (P, 9, 3) of probes there at MEASURE_FACE, in one batch on
    ``renderer``: how the add-on's Lighting Auto bakes auto_light_batches' batches."""
    return lambda points: monomial_coefficients(bake_sh_points(renderer, points, MEASURE_FACE))


def auto_light(renderer, at, boxes, names, tolerance: float) -> AutoLight:
    """auto_light_batches baked on ``renderer`` here."""
    return run_batches(auto_light_batches(at, boxes, names, tolerance), measure_bake(renderer))
