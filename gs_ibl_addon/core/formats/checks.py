"""What every splat reader and entry point shares: the error type, its message form, the check made before any
work (``check_input``) and the extensions the readers take."""
from __future__ import annotations

import os


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
