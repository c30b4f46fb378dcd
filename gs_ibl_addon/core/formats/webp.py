"""Lossless WebP images as exact RGBA bytes (SOG's containers): through a decoder the host application supplies
(Blender's own image loader, registered by the extension: every Blender has it), else OpenImageIO, else Pillow.

OpenImageIO reads and writes WebP (checked: PyPI openimageio 3.0.21 in our venv, Debian's 3.1.18 beside Blender
5.2); Blender release builds are documented to bundle it (4.0 and later), but the bpy *module* on PyPI does not, so
Pillow is tried next, and without either the message says what to do. Two traps, both handled here:
  * OpenImageIO premultiplies colour by alpha on reading unless asked not to (``oiio:UnassociatedAlpha``); SOG
    keeps data, not colour, in alpha (opacity, a quaternion tag), so that would change the RGB bytes;
  * libwebp's lossless encoder drops RGB under alpha 0 (it is not asked for "exact" here), so a writer must not
    store data there: SOG's only such case is the colour of a fully transparent splat, which nothing shows.
"""
from __future__ import annotations

import os
import tempfile
from typing import Callable

import numpy as np

Decoder = Callable[[bytes], np.ndarray]  # WebP bytes -> (H, W, 4) uint8 RGBA, ValueError for an undecodable image
_decoders: list[Decoder] = []  # supplied by the host application, tried first


def use_decoder(decoder: Decoder) -> None:
    """Decode WebP with ``decoder`` before OpenImageIO and Pillow (Blender registers its image loader: the bpy
    module and distributions' builds may have neither library)."""
    if decoder not in _decoders:
        _decoders.insert(0, decoder)


def drop_decoder(decoder: Decoder) -> None:
    while decoder in _decoders:
        _decoders.remove(decoder)


class WebPUnavailable(RuntimeError):
    """No WebP codec can be imported in this Python."""


_ADVICE = ("install the 'openimageio' or 'Pillow' package into this Python, or convert the file to .ply or .spz "
           "(e.g. with PlayCanvas splat-transform)")


def _oiio():
    try:
        import OpenImageIO as oiio
    except ImportError:
        return None
    return oiio if "webp" in oiio.get_string_attribute("format_list").split(",") else None


def _pillow():
    try:
        from PIL import Image
    except ImportError:
        return None
    return Image


def decode(data: bytes) -> np.ndarray:
    """(H, W, 4) uint8 RGBA of a WebP image given as bytes; ValueError for bytes that are not a WebP image."""
    if data[:4] != b"RIFF" or data[8:12] != b"WEBP":
        raise ValueError(f"not a WebP image (starts with {data[:12]!r})")
    if _decoders:
        return _decoders[0](data)
    oiio = _oiio()
    if oiio is not None:
        fd, tmp = tempfile.mkstemp(suffix=".webp")  # OpenImageIO's Python API reads files, not bytes
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            try:
                return _decode_oiio(oiio, tmp)
            except ValueError as e:  # OpenImageIO names our temporary file: name the image instead
                raise ValueError(str(e).replace(tmp, "the image")) from None
        finally:
            os.unlink(tmp)
    image = _pillow()
    if image is not None:
        import io
        try:
            with image.open(io.BytesIO(data)) as im:
                return np.asarray(im.convert("RGBA"), np.uint8).copy()
        except (OSError, SyntaxError, ValueError) as e:
            raise ValueError(f"the WebP image cannot be decoded ({e})") from None
    raise WebPUnavailable(f"decoding WebP needs OpenImageIO or Pillow and neither is importable here; {_ADVICE}")


def _decode_oiio(oiio, path: str) -> np.ndarray:
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise ValueError(f"the WebP image cannot be decoded ({oiio.geterror()})")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.UINT8)
    finally:
        inp.close()
    if pixels is None or spec.nchannels not in (3, 4):
        raise ValueError(f"the WebP image cannot be decoded ({spec.nchannels} channels)")
    pixels = np.asarray(pixels, np.uint8).reshape(spec.height, spec.width, spec.nchannels)
    if spec.nchannels == 3:
        pixels = np.concatenate([pixels, np.full(pixels.shape[:2] + (1,), 255, np.uint8)], 2)
    return pixels


def encode_lossless(rgba: np.ndarray) -> bytes:
    """Lossless WebP bytes of an (H, W, 4) uint8 image (RGB under alpha 0 is not kept: see the module note)."""
    rgba = np.ascontiguousarray(rgba, np.uint8)
    h, w, _ = rgba.shape
    oiio = _oiio()
    fd, tmp = tempfile.mkstemp(suffix=".webp")
    os.close(fd)
    try:
        if oiio is not None:
            spec = oiio.ImageSpec(w, h, 4, oiio.UINT8)
            spec.attribute("oiio:UnassociatedAlpha", 1)
            spec.attribute("compression", "lossless")
            out = oiio.ImageOutput.create(tmp)
            if out is None or not out.open(tmp, spec) or not out.write_image(rgba):
                raise OSError(f"writing a WebP image failed ({oiio.geterror()})")
            out.close()
        elif _pillow() is not None:
            _pillow().fromarray(rgba, "RGBA").save(tmp, "WEBP", lossless=True, exact=True)
        else:
            raise WebPUnavailable(f"writing WebP needs OpenImageIO or Pillow and neither is importable here; "
                                  f"{_ADVICE}")
        with open(tmp, "rb") as f:
            return f.read()
    finally:
        os.unlink(tmp)
