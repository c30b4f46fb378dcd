"""Colour transfer curves and the splat colour rule, in one place for the core, the overlay and the image writers
(no dependencies beyond numpy, so that code Blender loads never pulls in an image library).

The colour rule: a splat's SH evaluates to c(d) = SH(d) + 0.5 toward direction d. What c means depends on what the
scene was trained on, its *colour space*:
  * "srgb": 3DGS captures are trained on sRGB photos, so c is an sRGB-encoded value and the light it stands for is
    srgb_to_linear(c). Blender 5.3 (Cycles' gsplat_radiance: color_srgb_to_linear_v3(color + 0.5)) and NVIDIA's
    vk_gaussian_splatting decode it so; it is the default for files from outside.
  * "linear": c is scene-linear radiance already (HDR-trained captures, gs-ibl's synthetic scenes and sample).
Either way negative values give no light (max(c, 0)); nothing is clamped above, so a bright sRGB value stays bright.
"""
from __future__ import annotations

import numpy as np

from .sh import C0

COLOUR_SPACES: tuple[str, ...] = ("srgb", "linear")  # core/settings.py has the labels and the "auto" choice


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve on [0, 1] linear values."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB decoding curve, extended as Blender's Cycles extends it (intern/cycles/util/color.h,
    color_srgb_to_linear): negatives -> 0, below 0.04045 linear (c / 12.92), above it ((c + 0.055) / 1.055)^2.4
    on any value, 1 and beyond included (no clamp: sRGB 2 is linear 5.0)."""
    c = np.asarray(c, np.float64)
    return np.where(c < 0.04045, np.maximum(c, 0.0) / 12.92,
                    np.power((np.maximum(c, 0.04045) + 0.055) / 1.055, 2.4))


_TOE = 0.04045 / 12.92


def linear_to_srgb_extended(x: np.ndarray) -> np.ndarray:
    """The exact inverse of srgb_to_linear on x >= 0, unclamped above 1 (linear 5.0 -> sRGB 2.0); negatives -> 0.

    What a splat must store for Blender's sRGB decoding to give linear radiance x (linear scenes as native splats).
    """
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    # the toe ends where srgb_to_linear's does (0.04045 / 12.92), not at the rounded 0.0031308: exact both sides
    return np.where(x < _TOE, 12.92 * x, 1.055 * np.power(np.maximum(x, _TOE), 1.0 / 2.4) - 0.055)


def linear_sh_for_srgb_rule(sh: np.ndarray) -> np.ndarray:
    """SH (N, K, 3) of a linear scene re-encoded so that Blender's rule, radiance = srgb_to_linear(SH(d) + 0.5),
    gives the radiance the linear rule gave, max(SH(d) + 0.5, 0).

    The DC colour, which carries nearly all of a probe's light, is exact (linear_to_srgb_extended); the curve is not
    linear, so view-dependent bands (K > 1) are scaled by its slope at the DC colour: exact to first order in their
    size. Where the DC colour is 0 or below (no light) the bands are kept as they are.
    """
    sh = np.asarray(sh)
    out = np.array(sh, np.float32, copy=True)
    # The curve per splat and channel in float64; the bands, 15 of every 16 values, scaled in float32 (a float64
    # copy of them made a 1M-splat import 3.8 s slower and changes their float32 values by at most one rounding).
    c = C0 * sh[:, 0].astype(np.float64) + 0.5
    enc = linear_to_srgb_extended(c)
    out[:, 0] = (enc - 0.5) / C0
    if sh.shape[1] > 1:
        # d enc / d c: 12.92 in the linear toe, (1.055 / 2.4) c^(1/2.4 - 1) above it
        slope = np.where(c < _TOE, 12.92, (1.055 / 2.4) * np.power(np.maximum(c, _TOE), 1.0 / 2.4 - 1.0))
        slope = np.where(c > 0.0, slope, 1.0).astype(np.float32)
        out[:, 1:] *= slope[:, None, :]
    return out


def check_colour_space(space: str, who: str = "colour space") -> str:
    """``space`` if it is one of COLOUR_SPACES, else ValueError naming ``who`` and the choices."""
    if space not in COLOUR_SPACES:
        raise ValueError(f"{who} {space!r}: use one of {', '.join(COLOUR_SPACES)} "
                         "(srgb: trained on photos, as Blender reads splats; linear: HDR-trained or synthetic)")
    return space


def splat_radiance(c: np.ndarray, space: str) -> np.ndarray:
    """The light a splat emits from its evaluated colour c = SH(d) + 0.5, under the scene's colour space.

    The numpy mirror of splat_radiance() in shaders/splat_common.glsl: the one place the rule is applied."""
    c = np.asarray(c, np.float64)
    return srgb_to_linear(c) if check_colour_space(space) == "srgb" else np.maximum(c, 0.0)
