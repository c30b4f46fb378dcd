"""Error estimates that choose a probe's settings from a tolerance (docs/accuracy.md, "Settings from a tolerance").

What the error is. Probe faces dilate every splat by one size, a 1024^2 face's pixel, at every face size
(render/splat_math.py), so a coarse face is the same radiance read at fewer points and converges on the finer ones
without a bias of its own: what is left is where a texel's centre falls on an edge (a lamp's rim, a window's
frame) or on a splat far below a texel. That error falls at least as fast as the texel's width (first order) and
usually faster (the sample room's: 0.86% at 32^2, 0.10% at 64^2).

The estimate. The error at the finer of two sizes rendered is the geometric tail of the change between them,
change x r^k / (1 - r^k) after k doublings, with r the error's fall per doubling: 0.5 (first order, the slowest)
until two changes measure it (per face, once a face has changed twice), then their ratio clamped to
TAIL_RATIO_RANGE. Sizes not yet rendered are predicted by the same fall. Against a 1024^2 truth the estimate at 64^2
from 32^2 was 2.6-10x the true error on the sample
room, the guitar capture and the synthetic scenes (docs/accuracy.md), 2.6x on a starfield of splats far below a
texel.

Per cube face. Irradiance is linear in radiance, so a change between two cubes splits exactly into six parts, the
irradiance each face's change makes (probe/reference.py exact_irradiance_parts); each face's part falls with its
own size, so a lamp's face is rendered finer and a dim wall's is kept (ErrorModel.plan_faces).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .settings import IRRADIANCE_SIZES, MAX_TOLERANCE, MIN_TOLERANCE

TAIL_RATIO = 0.5  # the error's fall per doubling until two changes measure it: first order
TAIL_RATIO_RANGE = (0.35, 0.8)  # a measured fall is clamped here (order between 0.3 and 1.5)


def check_tolerance(value) -> float:
    """The tolerance as a float, or a ValueError saying what range it must be in and why."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not np.isfinite(value):
        raise ValueError(f"tolerance {value!r} must be a number: the relative RMS irradiance error allowed "
                         "(0.01 = 1%)")
    if not MIN_TOLERANCE <= float(value) <= MAX_TOLERANCE:
        raise ValueError(f"tolerance {value:g} is outside {MIN_TOLERANCE:g}-{MAX_TOLERANCE:g}: it is the relative "
                         f"RMS irradiance error allowed (0.01 = 1%); below {100 * MIN_TOLERANCE:g}% the render's own "
                         "error floor is near and the estimate is not validated, above 50% nothing is left to trust")
    return float(value)


def tail(ratio: float, doublings: float) -> float:
    """The error left at the finer size per unit of change, after a step of ``doublings`` doublings."""
    q = ratio ** max(doublings, 1e-9)
    return q / (1.0 - q)


@dataclass
class ErrorModel:
    """The render error of a probe against its face size, from the changes between the sizes rendered."""
    tail_ratio: float = TAIL_RATIO
    last: tuple[int, float, float] | None = None  # (face, change, doublings) of the last uniform step
    changes: list[tuple[int, int, float]] = field(default_factory=list)
    parts: np.ndarray | None = None  # (6, ...) each cube face's part of the irradiance change it last made
    part_steps: np.ndarray | None = None  # (6, 2) the (coarse, fine) face sizes of each face's last change
    part_ratios: np.ndarray | None = None  # (6,) each face's fall per doubling, measured once it changed twice
    scale: float = 1.0  # the RMS of the irradiance the parts are relative to
    kind: str = "change"

    def calibrate(self, coarse: int, fine: int, change: float) -> float:
        """Take the measured change between two rendered sizes; returns the estimated error at ``fine``."""
        steps = max(np.log2(fine / coarse), 1e-9)
        if self.changes:
            prev = self.changes[-1][2]
            per = (change / prev) ** (1.0 / steps) if prev > 0 else TAIL_RATIO_RANGE[0]
            self.tail_ratio = float(np.clip(per, *TAIL_RATIO_RANGE))
        self.changes.append((coarse, fine, float(change)))
        self.last = (fine, float(change), float(steps))
        return self.estimate(fine)

    def estimate(self, face: int) -> float:
        """The predicted error at ``face`` from the last step (at the last rendered size: its estimate)."""
        if self.last is None:
            return float("inf")
        f0, change, steps = self.last
        return float(change * tail(self.tail_ratio, steps) * self.tail_ratio ** max(np.log2(face / f0), 0.0))

    def change(self, coarse: np.ndarray, fine: np.ndarray) -> float:
        """The measured change between two sizes' irradiance that calibrate takes."""
        return relative_rms(coarse, fine)

    def next_face(self, tolerance: float, current: int, largest: int) -> int:
        """The next size to render: twice ``current`` (the tail has no shape to jump with), at most ``largest``."""
        return min(current * 2, largest)

    def take_parts(self, parts: np.ndarray, coarse, fine, irradiance: np.ndarray) -> None:
        """Each face's part of a change (``parts[f]``: the irradiance that face f's texels changed by going from
        size ``coarse[f]`` to ``fine[f]``; faces not in the change keep their last part), relative to
        ``irradiance``."""
        coarse, fine = np.asarray(coarse, np.int64), np.asarray(fine, np.int64)
        moved = fine > coarse
        if self.parts is None:
            self.parts = np.zeros_like(parts, dtype=np.float64)
            self.part_steps = np.stack([coarse, fine], 1)
            self.part_ratios = np.full(6, self.tail_ratio)
        for f in np.flatnonzero(moved):  # a face's second change measures its own fall
            before, after = np.sqrt(np.mean(self.parts[f] ** 2)), np.sqrt(np.mean(parts[f] ** 2))
            if before > 0 and self.part_steps[f, 1] == coarse[f]:
                per = (after / before) ** (1.0 / max(np.log2(fine[f] / coarse[f]), 1e-9))
                self.part_ratios[f] = float(np.clip(per, *TAIL_RATIO_RANGE))
        self.parts[moved] = parts[moved]
        self.part_steps[moved] = np.stack([coarse, fine], 1)[moved]
        self.scale = max(float(np.sqrt(np.mean(np.asarray(irradiance, np.float64) ** 2))), 1e-12)

    def estimate_faces(self, sizes) -> float:
        """The predicted error of a cube whose faces are rendered at ``sizes`` (6,): each face's part of its last
        change, carried by the tail to that face's size, summed as irradiance (take_parts first)."""
        sizes = np.asarray(sizes, np.float64)
        coarse, fine = self.part_steps[:, 0].astype(np.float64), self.part_steps[:, 1].astype(np.float64)
        r = self.part_ratios
        g = np.array([tail(q, np.log2(b / a)) for q, a, b in zip(r, coarse, fine)]) * r ** np.maximum(
            np.log2(sizes / fine), 0.0)
        left = np.tensordot(g, self.parts, 1)
        return float(np.sqrt(np.mean(left ** 2)) / self.scale)

    def plan_faces(self, tolerance: float, largest: int) -> tuple[list[int], float]:
        """Per-face sizes (powers of two from each face's last size up to ``largest``) predicted to meet the
        tolerance at the least pixel cost: the face whose doubling removes the most predicted error per added pixel
        is doubled, until the estimate meets it or no face can grow. Returns (sizes, their estimate); a bake renders
        one doubling of each face the plan grows (next_sizes), so that a face's second change measures its own fall
        before it is made finer still."""
        sizes = [int(n) for n in self.part_steps[:, 1]]
        est = self.estimate_faces(sizes)
        while est > tolerance:
            best, gain = None, 0.0
            for f in range(6):
                if sizes[f] * 2 > largest:
                    continue
                trial = list(sizes)
                trial[f] *= 2
                g = (est - self.estimate_faces(trial)) / (3.0 * sizes[f] ** 2)
                if g > gain:
                    best, gain = f, g
            if best is None:
                break
            sizes[best] *= 2
            est = self.estimate_faces(sizes)
        return sizes, est

    def next_sizes(self, tolerance: float, largest: int) -> list[int]:
        """The per-face sizes to render next: one doubling of each face plan_faces would make finer."""
        now = [int(n) for n in self.part_steps[:, 1]]
        plan, _est = self.plan_faces(tolerance, largest)
        return [min(p, 2 * n) for p, n in zip(plan, now)]


def upsample2(cube: np.ndarray) -> np.ndarray:
    """(6, M, M, C) -> (6, 2M, 2M, C) by bilinear interpolation within each face (edges clamped): what a reader
    sampling between texels gets."""
    def axis(a: np.ndarray, ax: int) -> np.ndarray:
        lo = np.concatenate([np.take(a, [0], ax), np.take(a, range(a.shape[ax] - 1), ax)], ax)
        hi = np.concatenate([np.take(a, range(1, a.shape[ax]), ax), np.take(a, [-1], ax)], ax)
        even, odd = 0.75 * a + 0.25 * lo, 0.75 * a + 0.25 * hi
        out = np.stack([even, odd], ax + 1)
        shape = list(a.shape)
        shape[ax] *= 2
        return out.reshape(shape)
    return axis(axis(np.asarray(cube, np.float64), 1), 2)


def interpolation_error(coarse: np.ndarray, fine: np.ndarray) -> float:
    """Relative RMS of ``coarse`` read between its texels (bilinear, at ``fine``'s texel centres) against
    ``fine``, the same irradiance at twice the size."""
    up = upsample2(coarse)
    return float(np.sqrt(np.mean((up - fine) ** 2)) / max(np.sqrt(np.mean(fine ** 2)), 1e-12))


def relative_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS of a - b over the RMS of b (all channels pooled)."""
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(np.sqrt(np.mean(b ** 2)), 1e-12))


def search_face(probe_at: Callable[[int], Any], model: ErrorModel, tolerance: float, first: int, largest: int,
                say: Callable[[str, float], None]) -> tuple[Any, int, list[dict], float]:
    """Render ``first`` and twice it, then wherever the model predicts the tolerance is met, until the estimate at
    the last size rendered meets it or ``largest`` is reached. ``probe_at(face)`` returns an object with an
    ``irradiance`` array. Returns (the last probe, its face, the trials, its estimated error)."""
    face = min(first, largest)
    say(f"rendering a {face}x{face} cubemap", 0.1)
    result = probe_at(face)
    trials: list[dict] = [{"face_size": face, "change": None, "estimate": None}]
    est = float("inf")
    while face < largest:
        coarse = face
        face = min(face * 2, largest) if len(trials) == 1 else model.next_face(tolerance, face, largest)
        say(f"rendering a {face}x{face} cubemap", min(0.8, 0.1 + 0.15 * len(trials)))
        finer = probe_at(face)
        changes = model.change(result.irradiance, finer.irradiance)  # one per probe with a batch's model
        est = model.calibrate(coarse, face, changes)
        change = float(np.max(changes))
        trials.append({"face_size": face, "change": change, "estimate": est})
        say(f"{face}x{face}: irradiance moved {100 * change:.2f}% from {coarse}x{coarse}; estimated error "
            f"{100 * est:.2f}% ({model.kind} model)", min(0.8, 0.1 + 0.15 * len(trials)))
        result = finer
        if est <= tolerance:
            break
    return result, face, trials, est


def choose_irradiance_size(irradiance_at: Callable[[int], np.ndarray], tolerance: float
                           ) -> tuple[int, np.ndarray, dict[int, float]]:
    """The smallest of IRRADIANCE_SIZES whose reads between texels (interpolation_error against twice the size)
    meet the tolerance, else the largest; returns (size, its irradiance, the error of each size tried)."""
    irr = {m: irradiance_at(m) for m in (IRRADIANCE_SIZES[0],)}
    errors: dict[int, float] = {}
    for m in IRRADIANCE_SIZES:
        irr[2 * m] = irradiance_at(2 * m)
        errors[m] = interpolation_error(irr[m], irr[2 * m])
        if errors[m] <= tolerance:
            return m, irr[m], errors
    return IRRADIANCE_SIZES[-1], irr[IRRADIANCE_SIZES[-1]], errors


def plan_text(settings: dict) -> str:
    """One line for the command line and Blender's report: what the tolerance chose and the estimated error."""
    plan = settings.get("tolerance_plan") or {}
    if "estimated_error" not in plan:
        return ""
    tol = settings.get("tolerance", 0.0)
    est = plan["estimated_error"]
    verdict = "meets" if plan.get("met") else "does NOT meet (largest face reached)"
    sizes = plan.get("face_sizes")
    if sizes and len(set(sizes)) > 1:
        from .cubemap import FACE_NAMES
        faces = "faces rendered at " + ", ".join(f"{n} {k}^2" for n, k in zip(FACE_NAMES, sizes)) + \
            f" (written at {plan['face_size']}^2)"
    else:
        faces = f"faces {plan['face_size']}^2"
    parts = [f"tolerance {100 * tol:g}%: {faces}, estimated error {100 * est:.2f}% "
             f"({plan['model']} model), {verdict} it"]
    between = plan.get("irradiance_between_texels")
    if between:
        m = str(plan["irradiance_size"])
        parts.append(f"irradiance {m}^2 (between texels {100 * between.get(m, float('nan')):.2f}%)")
    if "sh_error" in plan:
        parts.append(f"9 SH coefficients alone {100 * plan['sh_error']:.2f}%")
    if "lod_error" in plan:
        parts.append(f"level of detail {plan['lod']} (its error {100 * plan['lod_error']:.2f}%)")
    return "; ".join(parts)
