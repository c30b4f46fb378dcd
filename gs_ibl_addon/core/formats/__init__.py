"""Splat file formats. Each reader returns a validated, activated SplatScene; nothing downstream knows the format.

``read_scene(path)`` picks the reader from the file's content (and its extension where content cannot tell).
"""
from __future__ import annotations

import os

from ..scene import SplatScene


class SplatFormatError(ValueError):
    """Bad splat input: the message names the file, the field and what to do."""


def fail(path: str, what: str, todo: str | None = None) -> SplatFormatError:
    """The error every reader raises: ``<file>: <what is wrong>``, then `` (<what to do>)`` when given separately."""
    return SplatFormatError(f"{path}: {what}" + (f" ({todo})" if todo else ""))


# extension -> human description; the Blender importer's file browser filter is built from this.
EXTENSIONS = {".ply": "3DGS PLY (standard or SuperSplat compressed)", ".spz": "Niantic SPZ", ".splat": "antimatter15 .splat"}


def read_scene(path: str | os.PathLike) -> SplatScene:
    """Read any supported splat file into a SplatScene."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise fail(path, "no such file")
    with open(path, "rb") as f:
        head = f.read(4096)
    ext = os.path.splitext(path)[1].lower()
    if head.startswith(b"ply"):
        header = head.split(b"end_header", 1)[0]
        if b"element chunk" in header or b"packed_position" in header:
            from .compressed_ply import read_compressed_ply
            return read_compressed_ply(path)
        from .ply import read_ply
        return read_ply(path)
    if ext == ".spz" or head[:2] == b"\x1f\x8b" or head[:4] == b"NGSP":
        from .spz import read_spz
        return read_spz(path)
    if ext == ".splat":
        from .splat import read_splat
        return read_splat(path)
    raise fail(path, f"not a splat file this add-on reads (expected {', '.join(EXTENSIONS)}); "
                     f"the first bytes are {head[:8]!r}")
