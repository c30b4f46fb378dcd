"""How the extension recognises its own datablocks: the custom property ``gs_ibl`` holding a role.

Names are the user's to change and to reuse (a user may have a World called "GS-IBL World"), so our images,
Worlds, node groups and materials are found by this marker, never by name; a datablock of the user's with the
same name is left alone and ours gets Blender's .001 suffix.
"""
from __future__ import annotations

import bpy
import numpy as np

MARKER = "gs_ibl"


def is_ours(idb, role: str) -> bool:
    """``idb`` is a local datablock we made for ``role`` (linked ones belong to another file: never edited)."""
    return idb is not None and idb.get(MARKER) == role and idb.library is None


def find_ours(collection, role: str):
    """The first local datablock of ``collection`` (e.g. bpy.data.worlds) marked with ``role``, or None."""
    return next((idb for idb in collection if is_ours(idb, role)), None)


PROBE_NAME = "GS-IBL Probe"  # the name Add Probe gives; probes are recognised by is_probe


def is_probe(obj) -> bool:
    """Whether ``obj`` (an Object or None) is a GS-IBL probe: an Empty whose settings say so."""
    return obj is not None and obj.type == "EMPTY" and obj.gs_ibl_probe.is_probe


def image_pixels(image: bpy.types.Image) -> np.ndarray:
    """An image's pixels as (H, W, 4) float32, row 0 at the bottom (Blender's order; packed_float_image's input)."""
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)


def packed_float_image(pixels: np.ndarray, image: bpy.types.Image | None, role: str, name: str) -> bpy.types.Image:
    """Our packed float image of ``role`` (pixels (H, W, 3), row 0 at the bottom: the grid's atlas, the light
    volume's images), ``image`` updated in place when it is ours (scaled when the size changed), else a new one."""
    px = np.asarray(pixels, np.float32)
    h, w = px.shape[:2]
    img = image if is_ours(image, role) else None
    if img is not None and (tuple(img.size) != (w, h) or not img.is_float):
        img.scale(w, h)  # same datablock: the group's texture nodes keep pointing at it
    if img is None:
        img = bpy.data.images.new(name, w, h, alpha=False, float_buffer=True)
        img[MARKER] = role
        # data, not colour: no view transform may touch the coefficients (set before the pixels: setting the
        # colour space afterwards empties the buffer, blender/world.py _save_exr)
        img.colorspace_settings.is_data = True
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = px
    img.pixels.foreach_set(rgba.ravel())
    img.file_format = "OPEN_EXR"  # packed as float: the coefficients are signed
    img.pack()
    img.update()
    return img
