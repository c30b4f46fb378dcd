"""Error estimates that choose a probe's settings from a tolerance (docs/accuracy.md, "Settings from a tolerance").

Why a model, not the change between sizes. A probe's irradiance error comes mostly from the render, and there
mostly from the anti-aliasing dilation: every splat is widened by a variance of DILATION_PX2 pixel^2, which makes
small bright splats (a lamp, a window's edge) send too much light at coarse faces. The change between two sizes
over-states the error while that bias is still large and under-states it once the faces resolve the splats (the
error then falls faster than the change suggests): doubling until the change is under 1% took the sample room to
512^2 where 256^2 was within 1%.

The model. Each splat's share of light that the dilation adds, delta^2 / (sigma^2 + delta^2) (sigma^2: the
splat's angular footprint variance seen from the probe, delta = sqrt(DILATION_PX2) x the pixel angle 2/N), averaged
with each splat's light as weight, gives a curve S(N) that only needs the splats, not a render. The error at face N
is taken as C x S(N); C comes from the change between two rendered sizes, C = change / (S(N1) - S(N2)). The
estimate is SAFETY x C x S(N), and never less than the two-size Richardson estimate for second-order convergence
(change / 3 after a doubling), which catches errors the dilation does not explain. Against a 1024^2 truth on every
synthetic scene, the sample room and the real guitar capture (docs/accuracy.md) it was 1.3-4.8x the true error from
64^2 to 512^2, and 1.9-7.4x predicted from the first pair (32^2, 64^2); it under-states only below 0.01%, where the
render's own floor takes over. With that model the next face is the smallest whose predicted error meets the
tolerance, so a bake jumps there instead of doubling through every size.

Without the splats on the host (a caller that keeps them on the GPU only) the estimate falls back to the geometric
tail of the changes: change x r / (1 - r), r the ratio of the last two changes per doubling (0.5 until there are
two).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .colour import splat_radiance
from .render.splat_math import DILATION_PX2
from .scene import SplatScene, sh_dc_to_rgb
from .settings import IRRADIANCE_SIZES, MAX_TOLERANCE, MIN_TOLERANCE

SAFETY = 1.3  # over the calibrated C x S(N), which came down to 0.99x the true error (sample_env, 256^2)
TAIL_RATIO_RANGE = (0.35, 0.8)  # the fallback's per-doubling ratio is clamped here (p between 0.3 and 1.5)


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


@dataclass(frozen=True)
class Footprints:
    """What the dilation bias of a probe at one position depends on, per splat."""
    weight: np.ndarray  # (N,) share of the probe's light (sums to 1)
    variance: np.ndarray  # (N,) angular footprint variance seen from the probe, rad^2
    face: np.ndarray | None = None  # (N,) the cube face (cubemap.FACE_NAMES order) each splat's centre lies in
    _per_face: dict = field(default_factory=dict, compare=False, repr=False)  # size -> (6,) S of each face there

    def excess(self, face: int) -> float:
        """S(face): the light-weighted share of each splat's footprint that the dilation adds at this face size."""
        d2 = DILATION_PX2 * (2.0 / float(face)) ** 2
        return float(np.sum(self.weight * d2 / (self.variance + d2)))

    def face_excess(self, sizes) -> np.ndarray:
        """(6,) S of each cube face's splats with that face rendered at ``sizes[f]``: a probe whose faces differ in
        size has the error C x sum of these (the biases are of one sign: excess light of small splats)."""
        out = np.empty(6)
        for f, n in enumerate(sizes):
            n = int(n)
            if n not in self._per_face:  # one pass over the splats per size, however many plans ask
                d2 = DILATION_PX2 * (2.0 / n) ** 2
                self._per_face[n] = np.bincount(self.face, weights=self.weight * d2 / (self.variance + d2),
                                                minlength=6)
            out[f] = self._per_face[n][f]
        return out

    def face_light(self) -> np.ndarray:
        """(6,) each cube face's share of the probe's light."""
        if "light" not in self._per_face:
            self._per_face["light"] = np.bincount(self.face, weights=self.weight, minlength=6)
        return self._per_face["light"]


def footprints(scene: SplatScene, position) -> Footprints | None:
    """Per-splat footprint statistics of ``scene`` seen from ``position``; None for a scene with no light."""
    p = scene.positions.astype(np.float64) - np.asarray(position, np.float64).reshape(1, 3)
    dist2 = np.maximum(np.einsum("ij,ij->i", p, p), 1e-12)
    q = scene.scales.astype(np.float64) ** 2
    # the footprint's area-equivalent variance, averaged over view directions (render/lod.py's mean_footprint)
    var = np.sqrt((q[:, 0] * q[:, 1] + q[:, 0] * q[:, 2] + q[:, 1] * q[:, 2]) / 3.0)
    ang = var / dist2
    lum = splat_radiance(sh_dc_to_rgb(scene.sh[:, 0]), scene.colour_space).mean(axis=1)
    w = scene.opacities.astype(np.float64) * np.maximum(lum, 0.0) * np.minimum(ang, 4 * np.pi)
    total = float(w.sum())
    if not np.isfinite(total) or total <= 0:
        return None
    from .cubemap import direction_to_face
    return Footprints(w / total, ang, direction_to_face(p)[0].astype(np.intp))


@dataclass
class ErrorModel:
    """The render error of a probe against its face size, calibrated on the sizes rendered so far."""
    prints: Footprints | None
    safety: float = SAFETY
    scale: float | None = None  # C of the footprint model
    tail_ratio: float = 0.5  # the fallback's per-doubling ratio
    last: tuple[int, float] | None = None  # (face, the second-order Richardson error there) of the last calibration
    changes: list[tuple[int, int, float]] = field(default_factory=list)

    @property
    def kind(self) -> str:
        return "footprint" if self.prints is not None else "tail"

    def calibrate(self, coarse: int, fine: int, change: float) -> float:
        """Take the measured change between two rendered sizes; returns the estimated error at ``fine``."""
        if self.changes:
            prev, steps = self.changes[-1][2], max(np.log2(fine / coarse), 1e-9)
            per = (change / prev) ** (1.0 / steps) if prev > 0 else TAIL_RATIO_RANGE[0]
            self.tail_ratio = float(np.clip(per, *TAIL_RATIO_RANGE))
        self.changes.append((coarse, fine, float(change)))
        if self.prints is not None:
            drop = self.prints.excess(coarse) - self.prints.excess(fine)
            if drop > 1e-9:
                self.scale = change / drop
        q = (coarse / fine) ** 2  # second-order convergence over the step (1/4 for a doubling)
        self.last = (fine, float(change * q / (1.0 - q)))
        return self.estimate(fine)

    def estimate(self, face: int) -> float:
        """The predicted error at ``face`` from the last calibration (at the last rendered size: its estimate)."""
        if self.last is None:
            return float("inf")
        f0, floor = self.last
        r = self.tail_ratio
        fall = r ** max(np.log2(face / f0), 0.0)  # the tail's decay from the last rendered size
        if self.prints is not None and self.scale:
            return float(max(self.safety * self.scale * self.prints.excess(face), floor * fall))
        change = self.changes[-1][2]
        return float(max(change * r / (1.0 - r), floor) * fall)

    def change(self, coarse: np.ndarray, fine: np.ndarray) -> float:
        """The measured change between two sizes' irradiance that calibrate takes."""
        return relative_rms(coarse, fine)

    def estimate_faces(self, sizes, base: int) -> float:
        """The predicted error of a cube whose faces are rendered at ``sizes`` (6,), the footprint model calibrated
        on uniform sizes up to ``base``; the Richardson floor falls per face with that face's share of light."""
        sizes = np.asarray(sizes, np.float64)
        f0, floor = self.last
        fall = self.tail_ratio ** np.maximum(np.log2(sizes / f0), 0.0)
        tail = floor * float(np.sum(self.prints.face_light() * fall))
        scale = float(np.max(self.scale)) if self.scale is not None else 0.0
        return float(max(self.safety * scale * float(np.sum(self.prints.face_excess(sizes))), tail))

    def plan_faces(self, tolerance: float, base: int, largest: int) -> tuple[list[int], float]:
        """Per-face sizes (powers of two from ``base`` up to ``largest``) predicted to meet the tolerance at the
        least pixel cost: the face whose doubling removes the most predicted error per added pixel is doubled,
        until the estimate meets it or no face can grow. Returns (sizes, their estimate)."""
        sizes = [int(base)] * 6
        est = self.estimate_faces(sizes, base)
        while est > tolerance:
            best, gain = None, 0.0
            for f in range(6):
                if sizes[f] * 2 > largest:
                    continue
                trial = list(sizes)
                trial[f] *= 2
                g = (est - self.estimate_faces(trial, base)) / (3.0 * sizes[f] ** 2)
                if g > gain:
                    best, gain = f, g
            if best is None:
                break
            sizes[best] *= 2
            est = self.estimate_faces(sizes, base)
        return sizes, est

    def calibrate_faces(self, before, after, change: float) -> None:
        """Take the measured change between a cube at face sizes ``before`` and one at ``after`` (per face): the
        footprint model's C from the drop it predicts."""
        drop = float(np.sum(self.prints.face_excess(before) - self.prints.face_excess(after)))
        if drop > 1e-9 and change > 0:
            self.scale = float(change) / drop

    def next_face(self, tolerance: float, current: int, largest: int) -> int:
        """The smallest power-of-two multiple of ``current`` (up to ``largest``) predicted to meet the tolerance;
        the fallback model only doubles (it has no shape to extrapolate with)."""
        if self.prints is None or not self.scale:
            return min(current * 2, largest)
        face = current * 2
        while face < largest and self.estimate(face) > tolerance:
            face *= 2
        return min(face, largest)


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
