"""Splat file formats. Each reader returns a validated, activated SplatScene; nothing downstream knows the format.

``read_scene(path)`` picks the reader from the file's content (and its extension where content cannot tell).
``check_input(path)`` is the check every entry point (command line, Blender's importer) makes before any work:
the path exists, is a file (or a SOG folder), can be read and is not empty, each with its own message.
"""
from __future__ import annotations

import os

from ..scene import SplatScene
from .checks import EXTENSIONS, SplatFormatError, check_input, fail, is_sog_folder

__all__ = ["EXTENSIONS", "SplatFormatError", "check_input", "fail", "is_sog_folder", "read_scene"]


def read_scene(path: str | os.PathLike) -> SplatScene:
    """Read any supported splat file (or SOG folder) into a SplatScene."""
    path = check_input(path)
    if os.path.isdir(path):
        from .sog import read_sog
        return read_sog(path)
    with open(path, "rb") as f:
        head = f.read(4096)
    ext = os.path.splitext(path)[1].lower()
    if head.startswith(b"ply"):
        header = head.split(b"end_header", 1)[0]
        if b"element chunk" in header or b"packed_position" in header:
            from .compressed_ply import read_compressed_ply
            return read_compressed_ply(path)
        from .colour_space import DEFAULT_FOR_FILES, declared_colour_space
        from .ply import read_ply
        scene = read_ply(path)
        scene.colour_space = declared_colour_space(path) or DEFAULT_FOR_FILES  # gs-ibl's own files say theirs
        return scene
    if head[:4] == b"PK\x03\x04" or ext == ".sog" or os.path.basename(path).lower() == "meta.json":
        from .sog import read_sog
        return read_sog(path)
    if head[:4] == b"glTF" or ext in (".glb", ".gltf"):
        from .gltf import read_gltf
        return read_gltf(path)
    if ext == ".ksplat":
        from .ksplat import read_ksplat
        return read_ksplat(path)
    if ext == ".spz" or head[:2] == b"\x1f\x8b" or head[:4] == b"NGSP":
        from .spz import read_spz
        return read_spz(path)
    if ext == ".splat":
        from .splat import read_splat
        return read_splat(path)
    raise fail(path, f"not a splat file this add-on reads (expected {', '.join(EXTENSIONS)}); "
                     f"the first bytes are {head[:8]!r}")
