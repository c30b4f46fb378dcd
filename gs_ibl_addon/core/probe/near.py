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

A probe can also be inside an object many sigmas from every splat: a capture's armchair is a closed shell of small
opaque splats, and a probe in it sees only the shell's inside (in the GUI hour, blue-green meshes and no warning;
the sigma check fired only inside the table's top). So the second check (``enclosure``) is how much of the probe's
view is hidden by splats close to it, closer than CLOSE_FRACTION of the capture's size: each splat within that
distance lays its footprint (opacity x its Gaussian's solid angle, 2 pi sigma^2 / d^2 over the two larger sigmas)
on a small cube of directions, a texel's splats hide 1 - exp(-their sum) of it, and a probe with more than ENCLOSED
hidden that close in every half of its sphere (all around it: a wall, a floor or a room's corner leave a half open)
is warned about, whatever the splats' colour or opacity (several faint layers hide as one opaque one does).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

NEAR_SIGMAS = 3.0
MIN_OPACITY = 0.1
MIN_MOVE = 0.01  # metres: a probe near only splats so small that under 1 cm takes it clear is not warned about
# (a capture's millimetre splats put every default probe within 3 sigma of one), unless it is inside one
_CHUNK = 1 << 20
# Enclosure: hidden share of the sphere above which the probe is said to be inside an object, "close" as a share
# of the capture's size (the 5-95 percentile box's diagonal: floaters far out do not count), the directions' cube
# and the samples of a footprint wider than a texel.
ENCLOSED = 0.75  # of the least hidden half of the sphere: a probe 30 cm from a room's corner has 0.62 (the
# room of core/synthetic.py, 77% of the whole sphere hidden), one inside a closed shell of splats 0.99, one inside a
# shell of opacity 0.3 splats 0.84
CLOSE_FRACTION = 0.1
MIN_ENCLOSING_OPACITY = 0.02
_ENCLOSURE_FACE = 16
_FOOTPRINT_SAMPLES = 16
_MAX_ENCLOSING = 200_000  # splats laid at most (a random subset beyond, each standing for its share of the rest)
_SIZE_SAMPLE = 100_000  # positions the capture's size is measured on


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


def _scene_terms(scene) -> tuple[float, np.ndarray, np.ndarray]:
    """(capture_size, each splat's largest sigma (at least 1e-12), the splats fainter than MIN_OPACITY): the same on
    every bake of a scene, so made once and kept on it (1.5 ms of each bake's host time on the sample room). A
    read scene's arrays are not changed in place; a scene given new ones is measured again."""
    arrays = (scene.positions, scene.scales, scene.opacities)
    kept = getattr(scene, "_near_terms", None)
    if kept is not None and all(a is b for a, b in zip(kept[0], arrays)):
        return kept[1]
    s = scene.scales
    terms = (capture_size(scene), np.maximum(np.maximum(np.maximum(s[:, 0], s[:, 1]), s[:, 2]), 1e-12),
             np.flatnonzero(scene.opacities < MIN_OPACITY))
    try:
        scene._near_terms = (arrays, terms)
    except AttributeError:  # a scene type without room for it: made anew each time
        pass
    return terms


def _distances(scene, position) -> np.ndarray:
    """Each splat centre's distance from the probe (float32 metres): the one pass over all splats that both
    checks read. Per axis, squared and summed in place: the same float32 values as einsum's row sums (three terms
    added in order), 0.05 ms against 0.2 ms on the sample room's 21,939 splats (norm's reduce: 0.5 ms)."""
    q = np.asarray(position, np.float64).astype(np.float32)
    p = scene.positions
    x, y, z = p[:, 0] - q[0], p[:, 1] - q[1], p[:, 2] - q[2]
    x *= x
    y *= y
    z *= z
    x += y
    x += z
    return np.sqrt(x, out=x)


def _candidates(scene, position, keep: int = 256, dist: np.ndarray | None = None) -> np.ndarray:
    """Splats (of opacity >= MIN_OPACITY) that can be within NEAR_SIGMAS, else the ``keep`` likeliest nearest: the
    distance over the largest sigma is a lower bound of the Mahalanobis distance and needs no rotation. ``dist``:
    _distances of the position, when already made."""
    _, largest, faint = _scene_terms(scene)
    bound = (_distances(scene, position) if dist is None else dist) / largest
    bound[faint] = np.inf
    near = np.flatnonzero(bound < NEAR_SIGMAS)
    if len(near) or len(bound) <= keep:
        return near if len(near) else np.flatnonzero(np.isfinite(bound))
    return np.argpartition(bound, keep)[:keep]


def capture_size(scene) -> float:
    """The diagonal of the box holding the middle 90% of the splats along each axis (metres)."""
    pos = scene.positions[::max(1, scene.count // _SIZE_SAMPLE)]
    lo, hi = np.percentile(pos, 5, axis=0), np.percentile(pos, 95, axis=0)
    return float(np.linalg.norm(hi.astype(np.float64) - lo))


@lru_cache(maxsize=2)
def _footprint_offsets(k: int = _FOOTPRINT_SAMPLES) -> np.ndarray:
    """(k, 2) points of a unit 2D Gaussian, spread evenly (a sunflower with Rayleigh-distributed radii); cached,
    read-only."""
    i = np.arange(k) + 0.5
    r = np.sqrt(-2.0 * np.log(1.0 - i / k))
    a = i * np.pi * (3.0 - np.sqrt(5.0))
    out = np.stack([r * np.cos(a), r * np.sin(a)], 1)
    out.flags.writeable = False
    return out


@lru_cache(maxsize=4)
def _halves(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(k, 6 n^2) float: which texels of an n^2 cube lie in each of ``k`` evenly spread half-spheres, and (k,) the
    solid angle of each. The same on every bake (cached: made anew it was 10 ms of each bake's host time; the
    solid angles are a second matrix product, whose BLAS threads cost ms to wake on a loaded machine)."""
    from ..cubemap import face_directions, texel_solid_angles
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    a = i * np.pi * (3.0 - np.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    axes = np.stack([r * np.cos(a), r * np.sin(a), z], 1)
    c = face_directions(n).reshape(-1, 3)
    c = c / np.linalg.norm(c, axis=1, keepdims=True)
    half = ((axes @ c.T) > 0.0).astype(np.float64)
    omega = texel_solid_angles(n)
    area = half @ np.broadcast_to(omega[None], (6, n, n)).reshape(-1)
    half.flags.writeable = area.flags.writeable = False
    return half, area


def _most_open_half(hidden: np.ndarray, k: int = 64) -> float:
    """The hidden share of the least hidden half of the sphere (of ``k`` evenly spread ones): near 1 only where
    splats close the probe in all around (inside an object), low beside a wall, a floor or in a room's corner.
    ``hidden``: (6, n, n) the solid angle hidden of each texel."""
    half, area = _halves(int(hidden.shape[1]), int(k))
    # einsum's own loop, not BLAS's: waking BLAS's threads for this 64 x 1536 product cost 5 ms a bake at load 7
    # (0.06 ms in one thread); the sums differ from BLAS's in the last bit at most (4e-16)
    return float(np.min(np.einsum("ij,j->i", half, hidden.reshape(-1)) / area))


def enclosure(scene, position, dist: np.ndarray | None = None) -> dict:
    """{"enclosed": the share of the probe's sphere of directions hidden by splats closer than "radius" (0..1),
    "around": that share in the least hidden half of the sphere, "radius": CLOSE_FRACTION of the capture's size,
    "distance": the distance of the hiding splats (the median, weighted by how much each hides; None when none are
    that close); ``dist``: _distances of the position, when already made}."""
    from ..cubemap import direction_to_face, texel_solid_angles
    none = {"enclosed": 0.0, "around": 0.0, "radius": 0.0, "distance": None}
    if scene is None or scene.count == 0:
        return none
    radius = CLOSE_FRACTION * _scene_terms(scene)[0]
    p = np.asarray(position, np.float64)
    near = np.flatnonzero((_distances(scene, p) if dist is None else dist) < radius)
    d = scene.positions[near].astype(np.float64) - p
    dist = np.linalg.norm(d, axis=1)
    keep = (dist < radius) & (dist > 1e-9) & (scene.opacities[near] >= MIN_ENCLOSING_OPACITY)
    idx, d, dist = near[keep], d[keep], dist[keep]
    if len(idx) == 0:
        return {**none, "radius": radius}
    share = 1.0
    if len(idx) > _MAX_ENCLOSING:
        share = len(idx) / _MAX_ENCLOSING
        pick = np.sort(np.random.default_rng(0).choice(len(idx), _MAX_ENCLOSING, replace=False))
        idx, d, dist = idx[pick], d[pick], dist[pick]
    u = d / dist[:, None]
    two = np.sort(scene.scales[idx].astype(np.float64), axis=1)[:, 1:]  # a surface splat's two larger sigmas
    beta = np.minimum(np.sqrt(two[:, 0] * two[:, 1]) / dist, 1.0)  # its angular sigma, seen from the probe
    cover = share * scene.opacities[idx].astype(np.float64) * np.minimum(2.0 * np.pi * beta ** 2, 2.0 * np.pi)
    n = _ENCLOSURE_FACE
    omega = texel_solid_angles(n)
    wide = cover > 4.0 * np.pi / (6 * n * n)  # wider than a texel: laid as samples of its footprint
    dirs, amount = [u[~wide]], [cover[~wide]]
    if np.any(wide):
        uw, bw = u[wide], beta[wide]
        a = np.where(np.abs(uw[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t1 = np.cross(uw, a)
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(uw, t1)
        off = _footprint_offsets()
        spread = uw[:, None] + bw[:, None, None] * (off[None, :, :1] * t1[:, None] + off[None, :, 1:] * t2[:, None])
        dirs.append(spread.reshape(-1, 3))
        amount.append(np.repeat(cover[wide] / len(off), len(off)))
    dirs, amount = np.concatenate(dirs), np.concatenate(amount)
    face, s_, t_ = direction_to_face(dirs)
    i = np.clip(((s_ + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    j = np.clip(((t_ + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    depth = np.zeros((6, n, n))
    np.add.at(depth, (face, j, i), amount)
    hidden = (1.0 - np.exp(-depth / omega[None])) * omega[None]
    enclosed = float(np.sum(hidden) / (4.0 * np.pi))
    around = _most_open_half(hidden)
    order = np.argsort(dist)
    weight = np.cumsum(cover[order])
    middle = float(dist[order][np.searchsorted(weight, 0.5 * weight[-1])])
    return {"enclosed": min(enclosed, 1.0), "around": min(around, 1.0), "radius": radius, "distance": middle}


def near_splats(scene, position) -> dict:
    """{"nearest_sigmas": the smallest distance in sigmas to a splat of opacity >= MIN_OPACITY,
    "splats_within": how many are nearer than NEAR_SIGMAS, "move": metres to move away from the nearest so it is
    NEAR_SIGMAS off (0 when already), "nearest": that splat's centre, and enclosure()'s "enclosed",
    "enclosed_around" (its "around"), "enclosure_radius" and "enclosure_distance"}."""
    if scene is None or scene.count == 0:
        return {"nearest_sigmas": float("inf"), "splats_within": 0, "move": 0.0, "nearest": None}
    dist = _distances(scene, position)
    enclosed = enclosure(scene, position, dist)
    around = {"enclosed": enclosed["enclosed"], "enclosed_around": enclosed["around"],
              "enclosure_radius": enclosed["radius"], "enclosure_distance": enclosed["distance"]}
    idx = _candidates(scene, position, dist=dist)
    if len(idx) == 0:
        return {"nearest_sigmas": float("inf"), "splats_within": 0, "move": 0.0, "nearest": None, **around}
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
            "nearest": scene.positions[k].astype(float).tolist(), **around}


def near_warning(record: dict | None, name: str | None = None) -> str | None:
    """A warning when the probe is within NEAR_SIGMAS of splats and must move at least MIN_MOVE to be clear of them
    (or is inside one, under 1 sigma), or when splats close to it hide more than ENCLOSED of its view (inside an
    object); None otherwise. ``name``: the splat object's, said in the warning."""
    if not record:
        return None
    of = f" of {name!r}" if name else ""
    out = []
    sigmas = record.get("nearest_sigmas", np.inf)
    if sigmas < NEAR_SIGMAS and (record["move"] >= MIN_MOVE or sigmas < 1.0):
        where = ", ".join(f"{v:.2f}" for v in record["nearest"])
        inside = "inside" if sigmas < 1.0 else "close to"
        out.append(f"the probe is {inside} splats{of}: {record['splats_within']} splat(s) within {NEAR_SIGMAS:g} "
                   f"sigma, the nearest at {sigmas:.2f} sigma (centre {where}); their colour fills much of its view "
                   f"and its light can be off by 10-70%: move the probe about {record['move']:.2f} m further from "
                   "them, into open space")
    if record.get("enclosed_around", 0.0) > ENCLOSED:
        out.append(f"the probe is inside splats{of}: {100 * record['enclosed']:.0f}% of its view, all around it, is "
                   f"hidden by splats within {record['enclosure_radius']:.2f} m (about "
                   f"{record['enclosure_distance']:.2f} m away), as inside an object of the capture; its light is "
                   "their colour, not the light around it: move the probe out into open space")
    return "; ".join(out) or None
