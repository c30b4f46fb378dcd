"""Float image files through OpenImageIO: EXR in and out, and an 8-bit PNG preview for people to look at.

EXR holds scene-linear values unchanged (float32, or half when asked: half keeps ~3 significant digits and
overflows above 65504, which is why it is opt-in). The PNG preview is a display image only (exposure, clip
to [0, 1], sRGB transfer curve, 8 bits); never read it back as data.
"""
from __future__ import annotations

import os

import numpy as np

from .colour import linear_to_srgb


class ImageIOError(IOError):
    """An image could not be read or written: the message names the file and what failed."""


_CHANNEL_NAMES = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


def _oiio():
    try:
        import OpenImageIO as oiio
    except ImportError as e:  # pragma: no cover - the pinned requirements install it
        raise ImageIOError("OpenImageIO is not importable: install the pinned 'openimageio' package "
                           "(pip install -r requirements.txt)") from e
    return oiio


def _as_hwc(path: str, array: np.ndarray) -> np.ndarray:
    a = np.asarray(array)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in _CHANNEL_NAMES:
        raise ImageIOError(f"{path}: image must be H x W x C with C in (1, 3, 4), got shape {a.shape}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ImageIOError(f"{path}: image has no pixels (shape {a.shape})")
    return a


def write_exr(path: str | os.PathLike, array: np.ndarray, half: bool = False) -> None:
    """Write an H x W x C (C = 1, 3 or 4) float array as an EXR; channels are named Y, RGB or RGBA."""
    oiio = _oiio()
    path = os.fspath(path)
    a = _as_hwc(path, array)
    if not np.all(np.isfinite(a)):
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise ImageIOError(f"{path}: refusing to write {bad} non-finite values (NaN/inf); fix the producer")
    h, w, c = a.shape
    spec = oiio.ImageSpec(w, h, c, oiio.HALF if half else oiio.FLOAT)
    spec.channelnames = _CHANNEL_NAMES[c]
    if c == 4:
        spec.alpha_channel = 3
    spec.attribute("compression", "zip")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise ImageIOError(f"{path}: the folder {parent} does not exist")
    out = oiio.ImageOutput.create(path)
    if out is None:
        raise ImageIOError(f"{path}: OpenImageIO has no writer for this file name ({oiio.geterror()})")
    try:
        if not out.open(path, spec):
            raise ImageIOError(f"{path}: cannot open for writing ({out.geterror()})")
        if not out.write_image(np.ascontiguousarray(a, dtype=np.float32)):
            raise ImageIOError(f"{path}: writing pixels failed ({out.geterror()})")
    finally:
        out.close()


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an image (EXR or anything OpenImageIO reads) as an H x W x C float32 array."""
    oiio = _oiio()
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ImageIOError(f"{path}: no such file")
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise ImageIOError(f"{path}: cannot open as an image ({oiio.geterror()})")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        if pixels is None:
            raise ImageIOError(f"{path}: reading pixels failed ({inp.geterror()})")
    finally:
        inp.close()
    return np.asarray(pixels, np.float32).reshape(spec.height, spec.width, spec.nchannels)


def write_png_preview(path: str | os.PathLike, hdr_rgb: np.ndarray, exposure: float = 0.0) -> None:
    """Write an 8-bit sRGB PNG of a linear HDR image for viewing: scale by 2**exposure, clip, sRGB-encode."""
    oiio = _oiio()
    path = os.fspath(path)
    a = _as_hwc(path, hdr_rgb)
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    rgb = np.nan_to_num(a[..., :3].astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0) * (2.0 ** exposure)
    img = np.round(linear_to_srgb(rgb) * 255.0).astype(np.uint8)
    out = oiio.ImageOutput.create(path)
    if out is None:
        raise ImageIOError(f"{path}: OpenImageIO has no writer for this file name ({oiio.geterror()})")
    try:
        if not out.open(path, oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.UINT8)):
            raise ImageIOError(f"{path}: cannot open for writing ({out.geterror()})")
        if not out.write_image(np.ascontiguousarray(img)):
            raise ImageIOError(f"{path}: writing pixels failed ({out.geterror()})")
    finally:
        out.close()
