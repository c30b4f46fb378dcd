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
