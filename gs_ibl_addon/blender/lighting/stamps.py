"""Bake stamps: which bake's pixels each of our images holds, so that undo and redo (undo.py) show the right light.

Blender's undo restores datablocks (the probe's settings and report, the World, the images' packed EXR data) but
not an image's pixels already in memory: after Ctrl+Z the World kept showing the undone bake's light under the
report of the one before. Each bake stamps its World and images with a bake id; after an undo or redo an image whose
restored stamp differs from the bake its pixels came from drops its buffers, so Blender decodes the restored packed
data (Image.buffers_free: no file access; Image.reload would also try to re-read a file and print an error).
Images saved as files (Pack Images off) cannot be brought back: the file holds the newest bake, and the panel says
so (stale_images).
"""
from __future__ import annotations

import itertools
import time

import bpy

BAKE_KEY = "gs_ibl_bake"  # on a probe's World and images: the id of the bake that wrote them
ROLES = ("world", "radiance_image", "irradiance_image")

_ids = itertools.count(1)
_in_memory: dict[str, str] = {}  # image name -> id of the bake whose pixels it holds in memory (or on disk)


def new_bake_id() -> str:
    # unique across sessions too: a reopened file's stamps never match a new bake's
    return f"{time.time_ns():x}-{next(_ids)}"


def stamp(probe: bpy.types.Object) -> str:
    """Mark what the probe's bake just wrote with a new bake id; returns it."""
    bake_id = new_bake_id()
    s = probe.gs_ibl_probe
    for role in ROLES:
        idb = getattr(s, role)
        if idb is not None:
            idb[BAKE_KEY] = bake_id
            if isinstance(idb, bpy.types.Image):
                _in_memory[idb.name] = bake_id
    return bake_id


def _stamped_images():
    return [img for img in bpy.data.images if BAKE_KEY in img.keys()]


def restore_pixels() -> list[str]:
    """Make every stamped image show the bake its (restored) stamp names; returns the names of images that cannot
    (saved files overwritten by a later bake)."""
    stale = []
    for img in _stamped_images():
        want = str(img[BAKE_KEY])
        have = _in_memory.get(img.name)
        if have is None:  # loaded from a file, or a bake of an earlier session: Blender decoded it itself
            _in_memory[img.name] = want
        elif have != want:
            if img.packed_file is not None:
                img.buffers_free()  # decoded again from the restored packed EXR on next use
                _in_memory[img.name] = want
            else:
                stale.append(img.name)
    return stale


def stale_images(probe: bpy.types.Object) -> list[str]:
    """The probe's images whose pixels are not the bake their stamp names (after an undo, Pack Images off)."""
    s = probe.gs_ibl_probe
    out = []
    for role in ("radiance_image", "irradiance_image"):
        img = getattr(s, role)
        if img is not None and BAKE_KEY in img.keys() and _in_memory.get(img.name, img[BAKE_KEY]) != img[BAKE_KEY]:
            out.append(img.name)
    return out


def forget() -> None:
    """Another file is loaded (or the extension unregistered): its images' names mean nothing now."""
    _in_memory.clear()
