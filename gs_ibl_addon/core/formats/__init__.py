"""Splat file formats. Each reader returns a validated, activated SplatScene; nothing downstream knows the format.

``read_scene(path)`` picks the reader from the file's content (and its extension where content cannot tell).
``check_input(path)`` is the check every entry point (command line, Blender's importer) makes before any work:
the path exists, is a file (or a SOG folder), can be read and is not empty, each with its own message.
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
EXTENSIONS = {
    ".ply": "3DGS PLY (standard or SuperSplat compressed)",
    ".spz": "Niantic SPZ",
    ".splat": "antimatter15 .splat",
    ".ksplat": "GaussianSplats3D .ksplat",
    ".sog": "PlayCanvas SOG (zip)",
    ".json": "PlayCanvas SOG folder (its meta.json)",
    ".glb": "glTF binary with KHR_gaussian_splatting",
    ".gltf": "glTF with KHR_gaussian_splatting",
}
_NAMES = "a .ply, .spz, .splat, .ksplat, .sog, .glb/.gltf file or a SOG folder"


def is_sog_folder(path: str) -> bool:
    return os.path.isdir(path) and os.path.isfile(os.path.join(path, "meta.json"))


def check_input(path: str | os.PathLike, option: str | None = None) -> str:
    """The path as a str if it names something a reader can open; else one SplatFormatError saying what to do.

    ``option`` (e.g. "--input") is named in the message when given, so a user knows which argument is wrong.
    """
    path = os.fspath(path)
    who = f"{option} {path}" if option else path
    if not os.path.lexists(path):
        parent = os.path.dirname(os.path.abspath(path))
        where = "" if os.path.isdir(parent) else f" (the folder {parent} does not exist either)"
        raise fail(who, f"no such file{where}", "check the path and its spelling")
    if os.path.isdir(path):
        if is_sog_folder(path):
            return path
        raise fail(who, "is a folder, not a splat file", f"choose {_NAMES} inside it")
    if not os.path.exists(path):
        raise fail(who, "is a broken link: its target is missing", "point it at the splat file")
    if not os.path.isfile(path):
        raise fail(who, "is not a regular file (a device or a pipe?)", f"choose {_NAMES}")
    try:
        with open(path, "rb") as f:
            first = f.read(1)
    except PermissionError:
        raise fail(who, "cannot be read: permission denied",
                   "give yourself read access, e.g. chmod u+r, or copy the file somewhere you can read") from None
    except OSError as e:
        raise fail(who, f"cannot be read: {e.strerror or e}", "copy the file to a local disk") from None
    if not first:
        raise fail(who, "the file is empty (0 bytes): the download, copy or export did not finish",
                   "get or export the file again")
    return path


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
