"""Which way is up in a splat file, where the file says so.

Nothing in the 3DGS PLY layout records its axes: training output is usually OpenCV-like (y down, z forward), while
files made in other tools are y-up or z-up. Files gs-ibl writes for scenes it made (the bundled sample, synthetic
scenes) say theirs in a header comment, ``comment gs_ibl axes forward=Y up=Z`` (Blender's importer terms: the file's
axis that becomes Blender's forward +Y and up +Z), so that the importer's default brings them in upright.
"""
from __future__ import annotations

import os
import re

_PREFIX = "gs_ibl axes"
_AXIS = r"(-?[XYZ])"
_PATTERN = re.compile(rf"^comment {_PREFIX} forward={_AXIS} up={_AXIS}\s*$")
HEADER_LIMIT = 1 << 16  # a PLY header is a few hundred bytes; never read more than this looking for it
BLENDER_AXES = ("Y", "Z")  # forward, up of a file already in Blender's frame


def axes_comment(forward: str, up: str) -> str:
    """The comment (without PLY's leading ``comment ``) declaring a file's forward and up axes."""
    if not (re.fullmatch(_AXIS, forward) and re.fullmatch(_AXIS, up)) or forward.lstrip("-") == up.lstrip("-"):
        raise ValueError(f"forward {forward!r} and up {up!r} must be two different axes of X, Y, Z, -X, -Y, -Z")
    return f"{_PREFIX} forward={forward} up={up}"


def header_comments(path: str | os.PathLike) -> list[str]:
    """The text of a PLY header's ``comment`` lines (without ``comment ``); [] for a file that is not a PLY or
    cannot be read. Shared by every declaration gs-ibl writes into headers (axes here, colour space in
    formats/colour_space.py)."""
    try:
        with open(path, "rb") as f:
            head = f.read(HEADER_LIMIT)
    except OSError:
        return []
    if not head.startswith(b"ply"):
        return []
    lines = (raw.decode("ascii", "replace").strip() for raw in head.split(b"end_header", 1)[0].splitlines())
    return [line[len("comment "):] for line in lines if line.startswith("comment ")]


def declared_axes(path: str | os.PathLike) -> tuple[str, str] | None:
    """(forward, up) a PLY file's header declares, or None (not a PLY, no declaration, unreadable)."""
    for text in header_comments(path):
        m = _PATTERN.match("comment " + text)
        if m:
            return m.group(1), m.group(2)
    return None
