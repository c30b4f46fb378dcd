"""Where the light volume stands and how dense it is: "model no more than a scene needs".

- Region: the box over the boxes of everything it lights (every lit mesh over every frame of an animation: the
  caller passes one box per mesh and frame), grown by a margin, optionally cut to the splats' own box.
- Spacing: from the light itself. A coarse volume (COARSE_NODES a side at most, small faces) is baked over the
  region; between neighbouring nodes the change of the light, relative to its mean, per metre, is its gradient
  (luminance over the texels, volume_bake's maps); the spacing is the tolerance over the gradient's GRADIENT_QUANTILE
  (a few nodes beside a lamp do not set the whole volume), within MIN_SPACING .. the coarse spacing.
- Budget: a volume of more probes than ``budget`` is refused before any work with the spacing and the box that fit
  (VolumeTooLarge), or coarsened to fit and said so (``coarsen=True``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .grid import GridSpec
from .variation import LUMINANCE
from .volume import LightVolume, spacing_words

# Metres around the lit boxes. None: the lookup clamps a point outside the box to its face, and nodes beyond the lit
# surfaces only see what the surfaces do not (0.15 m put a node 2 cm under the sample room's lamp: the sphere below
# it read 2x its light at 0.4 m spacing; volume_bench.py, 2026-12-05).
MARGIN = 0.0
MIN_SPACING = 0.2  # metres: finer than this the probes see the splats' own blur, not the light
DEFAULT_BUDGET = 512  # probes: ~0.1 s each at 16^2 faces for the 22k-splat sample room on lavapipe (volume_bench.py)
MAX_NODES = 64  # a side: GridSpec's own limit
COARSE_NODES = 4
COARSE_FACE = 16
GRADIENT_QUANTILE = 0.9
DEFAULT_TOLERANCE = 0.1  # relative change of the light between neighbouring nodes


class VolumeTooLarge(ValueError):
    """A volume of more probes than the budget, refused before work; the message names what fits."""


@dataclass
class VolumePlan:
    spec: GridSpec
    spacing: float
    messages: list = field(default_factory=list)


def region_box(boxes, margin: float = MARGIN, within=None) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) over ``boxes`` (an iterable of (lo, hi) pairs) grown by ``margin``, cut to ``within`` (lo, hi)."""
    b = [(np.asarray(lo, np.float64), np.asarray(hi, np.float64)) for lo, hi in boxes]
    if not b:
        raise ValueError("a light volume needs at least one box to light (no lit mesh was given)")
    for lo, hi in b:
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError(f"box {lo.tolist()} .. {hi.tolist()} must be two points of three finite numbers")
    lo = np.min([x[0] for x in b], 0) - margin
    hi = np.max([x[1] for x in b], 0) + margin
    if within is not None:
        wlo, whi = (np.asarray(x, np.float64) for x in within)
        lo, hi = np.maximum(lo, wlo), np.minimum(hi, whi)
        if np.any(hi < lo):
            raise ValueError("the lit meshes lie outside the splats' box: no volume can light them (they keep the "
                             "World probe)")
    return lo, hi


def nodes_for(lo, hi, spacing: float) -> tuple[int, int, int]:
    """Nodes a side so that neighbours are at most ``spacing`` apart (one node on an axis thinner than a spacing's
    tenth)."""
    ext = np.asarray(hi, np.float64) - np.asarray(lo, np.float64)
    return tuple(int(1 if e < 0.1 * spacing else max(2, math.ceil(e / spacing - 1e-9) + 1)) for e in ext)


def plan_volume(boxes, spacing: float, budget: int = DEFAULT_BUDGET, margin: float = MARGIN, within=None,
                coarsen: bool = False, share: float = 1.0) -> VolumePlan:
    """The grid over ``boxes`` at ``spacing`` (metres), within ``share`` of ``budget`` probes (the rest: the
    bricks', volume_refine.py): refused (VolumeTooLarge, naming the spacing that fits and the box that fits this
    spacing) or, with ``coarsen``, coarsened and said so."""
    if not (spacing > 0 and math.isfinite(spacing)):
        raise ValueError(f"volume spacing {spacing!r} must be a positive number of metres")
    if int(budget) < 8:
        raise ValueError(f"probe budget {budget} must be 8 or more (a volume is at least 2 x 2 x 2)")
    lo, hi = region_box(boxes, margin, within)
    s = float(spacing)
    shape = nodes_for(lo, hi, s)
    messages = []
    fits = s
    limit = max(8, int(budget * share))
    what = f"the budget of {budget}" if limit == budget else f"the grid's {limit} of the budget of {budget}"
    while int(np.prod(shape)) > limit or max(shape) > MAX_NODES:
        fits *= 1.05
        shape = nodes_for(lo, hi, fits)
    if fits > s:
        count = int(np.prod(nodes_for(lo, hi, s)))
        ext = hi - lo
        side = (limit ** (1 / 3) - 1) * s
        if not coarsen:
            raise VolumeTooLarge(f"a light volume over {ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f} m at {s:.2f} m "
                                 f"spacing needs {count} probes, over {what}: use a spacing of {fits:.2f} m or "
                                 f"more, a budget of {math.ceil(count / share)} or more, or light a region of "
                                 f"about {side:.1f} m a side")
        messages.append(f"light volume coarsened from {s:.2f} m to {fits:.2f} m spacing: {count} probes were over "
                        f"{what}")
    spec = GridSpec(tuple(map(float, lo)), tuple(map(float, hi)), shape)
    messages.append(f"light volume: {spec.count} probes ({shape[0]} x {shape[1]} x {shape[2]}) over "
                    f"{hi[0] - lo[0]:.1f} x {hi[1] - lo[1]:.1f} x {hi[2] - lo[2]:.1f} m, {spacing_words(spec)}")
    return VolumePlan(spec, fits, messages)


def light_gradient(volume: LightVolume) -> np.ndarray:
    """Per pair of neighbouring nodes (along each axis), the mean absolute change of the irradiance texels'
    luminance over their mean, per metre: (pairs,)."""
    e = volume.irradiance @ LUMINANCE  # (nx, ny, nz, IRR, IRR)
    pts = volume.spec.points()
    out = []
    for a in range(3):
        if volume.spec.shape[a] < 2:
            continue
        e0, e1 = np.moveaxis(e, a, 0)[:-1], np.moveaxis(e, a, 0)[1:]
        step = np.linalg.norm(np.moveaxis(pts, a, 0)[1:] - np.moveaxis(pts, a, 0)[:-1], axis=-1)
        mean = np.maximum(0.5 * (e0 + e1).mean((-2, -1)), 1e-12)
        out.append((np.abs(e1 - e0).mean((-2, -1)) / mean / step).ravel())
    return np.concatenate(out) if out else np.zeros(0)


def spacing_from_light(volume: LightVolume, tolerance: float = DEFAULT_TOLERANCE) -> float:
    """The spacing at which the light changes by ``tolerance`` between neighbours (its gradient's quantile), within
    MIN_SPACING .. the coarse volume's own spacing."""
    from .volume import spec_spacing
    g = light_gradient(volume)
    coarse = spec_spacing(volume.spec)
    if len(g) == 0:
        return coarse
    grad = float(np.quantile(g, GRADIENT_QUANTILE))
    return float(np.clip(tolerance / max(grad, 1e-9), MIN_SPACING, max(coarse, MIN_SPACING)))


def choose_volume(renderer, boxes, tolerance: float = DEFAULT_TOLERANCE, budget: int = DEFAULT_BUDGET,
                  margin: float = MARGIN, within=None, coarsen: bool = True,
                  share: float = 1.0) -> tuple[VolumePlan, LightVolume]:
    """The plan for ``boxes`` from the light the splats in ``renderer`` give, the grid within ``share`` of
    ``budget``: a coarse volume measured first (also returned: a caller whose plan keeps the coarse spacing need not
    bake again)."""
    from .volume_bake import bake_volume
    lo, hi = region_box(boxes, margin, within)
    coarse_spacing = max(float(np.max(hi - lo)) / (COARSE_NODES - 1), MIN_SPACING)
    coarse = plan_volume([(lo, hi)], coarse_spacing, budget=max(budget, 8), margin=0.0, coarsen=True)
    measured = bake_volume(renderer, coarse.spec, face_size=COARSE_FACE, inside_test=False)
    spacing = spacing_from_light(measured, tolerance)
    plan = plan_volume([(lo, hi)], spacing, budget, margin=0.0, coarsen=coarsen, share=share)
    plan.messages.insert(0, f"light changes {100 * tolerance:.0f}% over {spacing:.2f} m (measured on "
                            f"{coarse.spec.count} probes)")
    return plan, measured

