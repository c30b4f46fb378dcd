"""WebP decoding by Blender's own image loader, for SOG files (core/formats/webp.py tries it first).

Every Blender reads WebP; OpenImageIO's Python module (official builds only) and Pillow may be missing. Loaded as
data (Non-Color) with straight alpha, the 8-bit channels come back as exactly byte/255 (checked in 4.2, 5.0, 5.3 on
random RGBA, RGB under alpha 0 included), so rounding recovers the bytes. The temporary image is removed again.
"""
from __future__ import annotations

import os
import tempfile

import bpy
import numpy as np

from ...core.formats import webp
from ..common.datablocks import image_pixels


def decode_webp(data: bytes) -> np.ndarray:
    """(H, W, 4) uint8 RGBA of a WebP image's bytes; ValueError when Blender cannot read it."""
    fd, path = tempfile.mkstemp(suffix=".webp")
    img = None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        try:
            img = bpy.data.images.load(path, check_existing=False)
        except RuntimeError as e:
            raise ValueError(f"the WebP image cannot be decoded ({e})".replace(path, "the image")) from None
        img.colorspace_settings.is_data = True
        img.alpha_mode = "STRAIGHT"
        if img.size[0] == 0 or img.size[1] == 0:
            raise ValueError("the WebP image cannot be decoded (Blender read no pixels)")
        return np.round(image_pixels(img)[::-1] * 255.0).astype(np.uint8)
    finally:
        if img is not None:
            bpy.data.images.remove(img)
        os.unlink(path)


def register() -> None:
    webp.use_decoder(decode_webp)


def unregister() -> None:
    webp.drop_decoder(decode_webp)
