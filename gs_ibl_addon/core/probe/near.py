"""A probe close to or inside splats: how far it is from them, in their own sigmas, and what to tell the user.

A splat is a fuzzy ellipsoid: seen from inside its footprint it covers half the sphere or more with its own
colour, and the cube's perspective projection of a Gaussian that close is far from the Gaussian (3DGS's local
affine approximation breaks down). Measured (benchmarks/stability_bench.py near, closed room, 64^2 faces, worst
channel's RMS against flat walls): thick wall splats (sigma 10 cm) 2.4% at 10 sigma, 8.5% at 3, 20% at 2, 46% at
1; thin ones (5 mm) at most 2.2% down to 4 sigma (2 cm), 67% in the splat layer. Measured in sigmas the two walls
fall on one curve, which is why the check counts sigmas rather than metres.

So the check is the probe's Mahalanobis distance to the splats (|S^-1 R^T (p - mu)|, in sigmas): a probe within
NEAR_SIGMAS of a splat of opacity at least MIN_OPACITY gets a warning with the distance to move. Only splats whose
centre is within NEAR_SIGMAS of their largest sigma are measured exactly (else the 256 nearest by that bound), so
the cost is one pass of vector arithmetic over the positions.
"""
from __future__ import annotations

import numpy as np

NEAR_SIGMAS = 3.0
MIN_OPACITY = 0.1
MIN_MOVE = 0.01  # metres: a probe near only splats so small that under 1 cm takes it clear is not warned about
# (a capture's millimetre splats put every default probe within 3 sigma of one), unless it is inside one
_CHUNK = 1 << 20


def _rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v for (M, 4) unit quaternions (w, x, y, z) and (M, 3) vectors."""
    w, u = q[:, :1], -q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def sigma_distances(scene, position, index: np.ndarray | None = None) -> np.ndarray:
    """The probe's distance from each splat's centre (or those of ``index``) in that splat's sigmas
    (Mahalanobis)."""
    p = np.asarray(position, np.float64)
    idx = np.arange(scene.count) if index is None else np.asarray(index)
    out = np.empty(len(idx))
    for s in range(0, len(idx), _CHUNK):
        e = idx[s:s + _CHUNK]
        q = scene.rotations[e].astype(np.float64)
        q /= np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
        local = _rotate_inverse(q, p - scene.positions[e].astype(np.float64))
        out[s:s + _CHUNK] = np.linalg.norm(local / np.maximum(scene.scales[e].astype(np.float64), 1e-12), axis=1)
    return out


def _candidates(scene, position, keep: int = 256) -> np.ndarray:
    """Splats (of opacity >= MIN_OPACITY) that can be within NEAR_SIGMAS, else the ``keep`` likeliest nearest: the
    distance over the largest sigma is a lower bound of the Mahalanobis distance and needs no rotation."""
    p = np.asarray(position, np.float32)
    bound = np.linalg.norm(scene.positions - p, axis=1) / np.maximum(scene.scales.max(axis=1), 1e-12)
    bound[scene.opacities < MIN_OPACITY] = np.inf
    near = np.flatnonzero(bound < NEAR_SIGMAS)
    if len(near) or len(bound) <= keep:
        return near if len(near) else np.flatnonzero(np.isfinite(bound))
    return np.argpartition(bound, keep)[:keep]


def near_splats(scene, position) -> dict:
    """{"nearest_sigmas": the smallest distance in sigmas to a splat of opacity >= MIN_OPACITY,
    "splats_within": how many are nearer than NEAR_SIGMAS, "move": metres to move away from the nearest so it is
    NEAR_SIGMAS off (0 when already), "nearest": that splat's centre}."""
    if scene is None or scene.count == 0:
        return {"nearest_sigmas": float("inf"), "splats_within": 0, "move": 0.0, "nearest": None}
    idx = _candidates(scene, position)
    if len(idx) == 0:
        return {"nearest_sigmas": float("inf"), "splats_within": 0, "move": 0.0, "nearest": None}
    m = sigma_distances(scene, position, idx)
    k = int(idx[np.argmin(m)])
    nearest = float(m.min())
    move = 0.0
    if nearest < NEAR_SIGMAS:
        # Along the line from the splat's centre through the probe, the distance in sigmas grows linearly: a
        # probe at m sigmas at metres d from the centre is at NEAR_SIGMAS sigmas at d * NEAR_SIGMAS / m. A probe
        # at the centre is told the splat's largest 3-sigma radius.
        d = float(np.linalg.norm(np.asarray(position, np.float64) - scene.positions[k]))
        move = d * (NEAR_SIGMAS / nearest - 1.0) if nearest > 1e-6 else NEAR_SIGMAS * float(scene.scales[k].max())
    return {"nearest_sigmas": nearest, "splats_within": int(np.sum(m < NEAR_SIGMAS)), "move": move,
            "nearest": scene.positions[k].astype(float).tolist()}


def near_warning(record: dict | None) -> str | None:
    """A warning when the probe is within NEAR_SIGMAS of splats and must move at least MIN_MOVE to be clear of them
    (or is inside one, under 1 sigma); None otherwise."""
    if not record or record.get("nearest_sigmas", np.inf) >= NEAR_SIGMAS:
        return None
    if record["move"] < MIN_MOVE and record["nearest_sigmas"] >= 1.0:
        return None
    where = ", ".join(f"{v:.2f}" for v in record["nearest"])
    inside = "inside" if record["nearest_sigmas"] < 1.0 else "close to"
    return (f"the probe is {inside} splats: {record['splats_within']} splat(s) within {NEAR_SIGMAS:g} sigma, the "
            f"nearest at {record['nearest_sigmas']:.2f} sigma (centre {where}); their colour fills much of its view "
            f"and its light can be off by 10-70%: move the probe about {record['move']:.2f} m further from them, "
            "into open space")
