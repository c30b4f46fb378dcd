"""Colour transfer curves, in one place for the core, the overlay and the image writers (no dependencies beyond
numpy, so that code Blender loads never pulls in an image library)."""
from __future__ import annotations

import numpy as np


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve on [0, 1] linear values."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
