"""Repairs every reader of raw float splats applies the same way, counted under the same names in ``scene.repairs``.

  ``dropped_nonfinite``  splats with NaN/inf values are dropped (by the reader: which fields it can check varies);
  ``clamped_scales``     splats with an axis scale below ``MIN_SCALE`` get that axis clamped to ``MIN_SCALE``;
  ``identity_rotations`` splats whose quaternion is exactly zero get the identity rotation.
Counts are kept in a dict with every key (``new_counts``); ``reported`` keeps the keys whose count is > 0.
"""
from __future__ import annotations

import numpy as np

REPAIRS = ("dropped_nonfinite", "clamped_scales", "identity_rotations")

# Below about 1e-12 an axis scale is degenerate: 1/scale^2 (the inverse covariance a renderer builds) nears float32
# overflow. The value is the PLY activation (exp in float64, rounded to float32) of a float32 raw value, so that a
# repaired scene written as PLY reads back unchanged.
MIN_SCALE = np.float32(np.exp(np.float64(np.float32(-27.6))))


def new_counts() -> dict[str, int]:
    return dict.fromkeys(REPAIRS, 0)


def reported(counts: dict[str, int]) -> dict[str, int]:
    """The repairs that happened: ``scene.repairs`` holds a key only when its count is > 0."""
    return {key: int(v) for key, v in counts.items() if v}


def clamp_scales(scales: np.ndarray, counts: dict[str, int]) -> None:
    """Clamp (N, 3) float32 scales below MIN_SCALE in place, counting the splats touched."""
    small = scales < MIN_SCALE
    counts["clamped_scales"] += int(small.any(1).sum())
    scales[small] = MIN_SCALE


def normalise_quaternions(q32: np.ndarray, counts: dict[str, int]) -> np.ndarray:
    """(N, 4) float32 quaternions -> unit float32 (normalised in float64); zero ones become the identity."""
    q = q32.astype(np.float64)
    n2 = np.einsum("ij,ij->i", q, q)
    zero = n2 == 0
    counts["identity_rotations"] += int(zero.sum())
    q[zero] = (1.0, 0.0, 0.0, 0.0)
    n2[zero] = 1.0
    out = (q / np.sqrt(n2)[:, None]).astype(np.float32)
    # Already unit to float32 precision: keep the stored bits, so that re-reading a written scene changes nothing.
    unit = np.abs(n2 - 1.0) <= 2.0 ** -21
    out[unit & ~zero] = q32[unit & ~zero]
    return out
