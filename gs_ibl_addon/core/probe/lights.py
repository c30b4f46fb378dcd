"""Lights from a probe: the few brightest compact regions of a radiance cube, split off as light descriptions.

A sun, a lamp or a window seen by the probe carries much of its light from a small solid angle. Baked into the
World it lights meshes without shadows (and SH order 2 rings around it, docs/stability.md); as a Blender light it
casts them. ``extract_lights`` finds such regions and splits each texel of one into the light's part (what rises
above the region's surroundings) and the rest, which stays in the probe: light + rest = the cube, so no power is
lost or counted twice.

Rule: a texel is bright when its luminance is over ``BRIGHT_FACTOR`` times the probe's solid-angle-weighted median
luminance (the walls, not the lamp); bright texels that touch (across cube edges too) form a region; a region is
a light when it carries at least ``MIN_SHARE`` of the probe's power and spans at most ``MAX_SOLID_ANGLE``; the
``count`` most powerful are kept. The region's surroundings are the mean of the texels bordering it. Regions are
found on a copy no finer than ``DETECT_SIZE`` per face (their outline is what matters) and split at full size.

A light's description (probe.json "lights"): direction (power-weighted mean, unit), solid_angle (sr, of its
bright texels at full size), angle (degrees: the diameter of a disc of that solid angle, Blender's sun angle),
irradiance (RGB: sum of the light's radiance x texel solid angle, the irradiance it gives a surface facing it, so
Blender's sun Strength and Color), share (its part of the probe's power).
"""
from __future__ import annotations

import numpy as np

from .. import cubemap
from .box import downsample_to_size

BRIGHT_FACTOR = 8.0
MIN_SHARE = 0.02
MAX_SOLID_ANGLE = 0.5  # sr: a cone of about 46 degrees across; larger is ambient, not a light
DETECT_SIZE = 64
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 luminance


def _neighbours(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (a, b) of flat texel indices (face * n * n + row * n + col) that touch, within faces and across
    edges."""
    idx = np.arange(6 * n * n).reshape(6, n, n)
    a = [idx[:, :, :-1].ravel(), idx[:, :-1, :].ravel()]
    b = [idx[:, :, 1:].ravel(), idx[:, 1:, :].ravel()]
    edge, across, _ = cubemap.edge_neighbours(n)
    a.append(idx[edge[:, 0], edge[:, 1], edge[:, 2]])
    b.append(idx[across[:, 0], across[:, 1], across[:, 2]])
    return np.concatenate(a), np.concatenate(b)


def _components(mask: np.ndarray, pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Label per flat texel: -1 outside ``mask``, else the smallest index of its connected region."""
    a, b = pairs
    keep = mask[a] & mask[b]
    a, b = a[keep], b[keep]
    label = np.where(mask, np.arange(mask.size), -1)
    while True:  # propagate the minimum label along edges until nothing changes (regions are small)
        m = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, m)
        np.minimum.at(new, b, m)
        new[mask] = new[new[mask]]  # pointer jumping: converges in about log(diameter) passes
        if np.array_equal(new, label):
            return label
        label = new


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    c = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(c, 0.5 * c[-1])])


def extract_lights(cube: np.ndarray, count: int, bright_factor: float = BRIGHT_FACTOR,
                   min_share: float = MIN_SHARE, max_solid_angle: float = MAX_SOLID_ANGLE
                   ) -> tuple[np.ndarray, list[dict]]:
    """(the cube without its lights, up to ``count`` light descriptions, most powerful first). count 0: the cube
    unchanged and no lights. Alpha, if any, is kept."""
    cube = np.asarray(cube, np.float32)
    if count <= 0:
        return cube, []
    n = cube.shape[1]
    rgb = cube[..., :3].astype(np.float64)
    omega = np.broadcast_to(cubemap.texel_solid_angles(n)[None], (6, n, n))
    small = downsample_to_size(rgb, DETECT_SIZE) if n > DETECT_SIZE else rgb
    m = small.shape[1]
    w_small = np.broadcast_to(cubemap.texel_solid_angles(m)[None], (6, m, m)).ravel()
    luma_small = (small @ LUMA).ravel()
    total = float(np.sum((rgb @ LUMA) * omega))
    if total <= 0:
        return cube, []
    threshold = bright_factor * max(weighted_median(luma_small, w_small), 1e-12)
    bright = luma_small > threshold
    pairs = _neighbours(m)
    label = _components(bright, pairs)
    # Each full-size texel's region is that of the detection texel holding it.
    scale = n // m
    full_label = label.reshape(6, m, m).repeat(scale, 1).repeat(scale, 2)
    found = []
    a, b = pairs
    for lab in np.unique(label[label >= 0]):
        inside = label == lab
        border = np.zeros(label.size, bool)  # texels next to the region, outside it
        border[b[inside[a] & ~inside[b]]] = True
        border[a[inside[b] & ~inside[a]]] = True
        surround = (small.reshape(-1, 3)[border] * w_small[border, None]).sum(0) / max(w_small[border].sum(), 1e-30)
        region = full_label == lab
        excess = np.where(region[..., None], np.maximum(rgb - surround, 0.0), 0.0)
        irr = (excess * omega[..., None]).sum((0, 1, 2))
        share = float(irr @ LUMA) / total
        lit = region & ((rgb @ LUMA) > threshold)  # the light's own outline, at full size
        solid = float(omega[lit].sum())
        if share < min_share or solid > max_solid_angle or solid <= 0:
            continue
        dirs = cubemap.face_directions(n)
        d = ((excess @ LUMA) * omega)[..., None] * dirs
        d = d.sum((0, 1, 2))
        found.append((share, excess, {
            "direction": (d / np.linalg.norm(d)).tolist(), "solid_angle": solid,
            "angle": float(np.degrees(2.0 * np.arccos(max(-1.0, 1.0 - solid / (2.0 * np.pi))))),
            "irradiance": irr.tolist(), "share": share}))
    found.sort(key=lambda f: -f[0])
    rest = cube.copy()
    for _, excess, _ in found[:count]:
        rest[..., :3] -= excess.astype(np.float32)
    return rest, [f[2] for f in found[:count]]


def lights_irradiance(lights: list[dict], normals: np.ndarray) -> np.ndarray:
    """E/pi the lights give (..., 3) unit normals, each as a distant source (a Blender sun): irradiance x
    max(0, n.l) / pi. Exact for a point source; a wide one's cosine is taken at its centre."""
    nrm = np.asarray(normals, np.float64)
    out = np.zeros(nrm.shape[:-1] + (3,))
    for light in lights:
        cos = np.maximum(nrm @ np.asarray(light["direction"]), 0.0)
        out += cos[..., None] * np.asarray(light["irradiance"]) / np.pi
    return out


def lights_text(lights: list[dict] | None) -> str | None:
    """One line for summaries, or None without lights."""
    if not lights:
        return None
    parts = [f"{100 * l['share']:.0f}% of the light from ({', '.join(f'{v:.2f}' for v in l['direction'])}), "
             f"{l['angle']:.1f} deg across" for l in lights]
    return f"lights split from the probe ({len(lights)}): " + "; ".join(parts)
