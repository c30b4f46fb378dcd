"""Clipped highlights: captures trained on 8-bit photos store a window, a lamp or the sky at the top of the range
(1.0), however bright the light was, so they light a mesh far less than the real light did. A probe can give
those directions back an intensity: every texel of the radiance cube whose colour sits at the top of the range is
multiplied by a gain, before filtering.

The gain is the user's (``highlight_gain``: the light's real radiance over 1.0; an exposure bracket or a light
meter gives it, 2^stops) or estimated (``"auto"``, ``estimate_gain``): the unclipped texels' luminance tail is
taken as a power law (P(Y > y) ~ y^-a, the Hill estimate over the brightest ``TAIL`` of them) and the clipped
texels are given the mean that law predicts above the clip, a / (a - 1) times the clip level. It is a guess from
the shape of the tail, and on a capture whose clipped light is much brighter than anything unclipped it is low
(docs/stability.md measures it): give the gain when it is known.

Two places, one rule. On the splats (``gain_clipped_splats``, what bake_probe does when it is given the scene):
a splat whose stored colour is clipped has its light multiplied by the gain, and the renderer blends it with its
neighbours as it would the real light. On the rendered cube (``recover_highlights``, for a caller that holds the
splats on the GPU only): clipped texels times the gain; texels where a clipped splat blends with its surroundings
fall below the clip and keep their value, so a small or blurred highlight gets much less than its due (measured in
docs/stability.md).
"""
from __future__ import annotations

import numpy as np

from .. import cubemap
from ..colour import srgb_to_linear
from ..sh import C0

CLIP = 0.98  # a splat colour (SH + 0.5, as stored) at or above this in its brightest channel counts as clipped
TAIL = 0.1  # the share of the unclipped sphere (by solid angle) whose luminance tail gives the auto estimate
MAX_AUTO_GAIN = 64.0
LUMA = np.array([0.2126, 0.7152, 0.0722])


def clip_level(colour_space: str) -> float:
    """The clip as linear radiance: the stored value CLIP decoded by the scene's colour rule."""
    return float(srgb_to_linear(CLIP)) if colour_space == "srgb" else CLIP


def _srgb_encode_extended(x: np.ndarray) -> np.ndarray:
    """The inverse of colour.srgb_to_linear on [0, inf) (extended above 1 as Cycles' curve is)."""
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def clipped_splats(scene) -> np.ndarray:
    """(N,) True for splats whose stored base colour (SH DC + 0.5) is at the top of the range in its brightest
    channel."""
    return (scene.sh[:, 0].astype(np.float64) * C0 + 0.5).max(-1) >= CLIP


def gain_clipped_splats(scene, gain: float | str):
    """(the scene with clipped splats' light times the gain (a copy; the same scene when the gain is 1), a record
    for probe.json or None). "auto" estimates the gain from the splats' own luminance tail (estimate_gain's rule
    over the unclipped splats, weighted by opacity x footprint area)."""
    import dataclasses
    if gain == 1 or gain == 1.0:
        return scene, None
    clipped = clipped_splats(scene)
    c = scene.sh[:, 0].astype(np.float64) * C0 + 0.5
    light = srgb_to_linear(c) if scene.colour_space == "srgb" else np.maximum(c, 0.0)
    area = scene.opacities.astype(np.float64) * np.prod(np.sort(scene.scales.astype(np.float64), 1)[:, 1:], 1)
    estimated = gain == "auto"
    g = _tail_gain(light @ LUMA, area, clipped) if estimated else float(gain)
    sh = scene.sh.copy()
    target = g * light[clipped]
    new_c = _srgb_encode_extended(target) if scene.colour_space == "srgb" else target
    sh[clipped, 0] = ((new_c - 0.5) / C0).astype(np.float32)
    if scene.colour_space == "linear" and sh.shape[1] > 1:  # view-dependent bands carry light too
        sh[clipped, 1:] *= np.float32(g)
    y = light @ LUMA
    before = float(np.sum(y * area))
    part = float(np.sum(y[clipped] * area[clipped]))
    record = {"gain": g, "estimated": bool(estimated), "clip": CLIP, "on": "splats",
              "splats": int(clipped.sum()), "fraction": float(clipped.mean()),
              "share_before": part / before if before > 0 else 0.0,
              "share_after": g * part / (before + (g - 1.0) * part) if before > 0 else 0.0}
    return dataclasses.replace(scene, sh=sh), record


def _tail_gain(y: np.ndarray, w: np.ndarray, clipped: np.ndarray) -> float:
    """a / (a - 1) of the Hill estimate over the brightest TAIL (by weight) of the unclipped values."""
    free = ~clipped & (y > 0) & (w > 0)
    yv, wv = y[free], w[free]
    if yv.size < 16:
        return 1.0
    order = np.argsort(yv)[::-1]
    yv, wv = yv[order], wv[order]
    tail = np.cumsum(wv) <= TAIL * wv.sum()
    tail[:2] = True
    hill = float(np.sum(wv[tail] * np.log(yv[tail] / yv[tail][-1])) / np.sum(wv[tail]))  # = 1 / a
    a = 1.0 / max(hill, 1e-6)
    return MAX_AUTO_GAIN if a <= 1.0 else float(np.clip(a / (a - 1.0), 1.0, MAX_AUTO_GAIN))


def clipped_mask(cube: np.ndarray, colour_space: str) -> np.ndarray:
    """(6, N, N) True where the texel's colour (un-premultiplied by its coverage) is at the top of the range, up to
    a little above 1 (trained colours overshoot 1.0 slightly; an HDR light far above it is not clipped)."""
    rgb = np.asarray(cube, np.float64)[..., :3]
    alpha = np.clip(np.asarray(cube)[..., 3], 1e-6, 1.0) if cube.shape[-1] == 4 else 1.0
    top = rgb.max(-1) / alpha
    return (top >= clip_level(colour_space)) & (top <= 1.1 * float(srgb_to_linear(1.0)))


def estimate_gain(cube: np.ndarray, colour_space: str) -> float:
    """The auto gain (module notes): a / (a - 1) from the Hill estimate of the unclipped luminance tail, in
    [1, MAX_AUTO_GAIN]."""
    n = cube.shape[1]
    w = np.broadcast_to(cubemap.texel_solid_angles(n)[None], (6, n, n))
    y = np.asarray(cube, np.float64)[..., :3] @ LUMA
    return _tail_gain(y.ravel(), w.ravel(), clipped_mask(cube, colour_space).ravel())


def recover_highlights(cube: np.ndarray, gain: float | str, colour_space: str) -> tuple[np.ndarray, dict | None]:
    """(the cube with clipped texels' RGB times the gain, a record for probe.json or None when the gain is 1).
    gain: a number >= 1, or "auto" (estimate_gain)."""
    cube = np.asarray(cube, np.float32)
    if gain == 1 or gain == 1.0:
        return cube, None
    estimated = gain == "auto"
    g = estimate_gain(cube, colour_space) if estimated else float(gain)
    mask = clipped_mask(cube, colour_space)
    n = cube.shape[1]
    w = cubemap.texel_solid_angles(n)[None]
    luma = cube[..., :3].astype(np.float64) @ LUMA
    before = float(np.sum(luma * w))
    out = cube.copy()
    out[mask, :3] *= np.float32(g)
    clipped_power = float(np.sum(np.where(mask, luma, 0.0) * w))
    return out, {"gain": g, "estimated": bool(estimated), "clip": CLIP, "on": "cube",
                 "fraction": float(np.sum(mask * w) / (4.0 * np.pi)),
                 "share_before": clipped_power / before if before > 0 else 0.0,
                 "share_after": g * clipped_power / (before + (g - 1.0) * clipped_power) if before > 0 else 0.0}


def highlight_text(record: dict | None) -> str | None:
    """One line for summaries, or None when no gain was applied."""
    if not record:
        return None
    how = "estimated" if record["estimated"] else "given"
    what = (f"{record['splats']:,} splats" if record.get("on") == "splats"
            else f"{100 * record['fraction']:.2f}% of the sphere")
    return (f"highlights: {what} clipped at the top of the range, "
            f"times {record['gain']:.3g} ({how}): {100 * record['share_before']:.0f}% -> "
            f"{100 * record['share_after']:.0f}% of the light")
