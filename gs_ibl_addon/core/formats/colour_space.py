"""Which colour rule a splat file was made for, where the file says so.

3DGS files do not record it: captures trained on photos hold sRGB-encoded colour (core/colour.py), which is what
Blender and most viewers assume. Files gs-ibl writes for scenes whose colours are linear radiance (the bundled
sample, synthetic scenes) say so in a PLY header comment, ``comment gs_ibl colour_space=linear``, so that reading
them with --colour-space auto (and importing them into Blender) uses the rule they were made for.
"""
from __future__ import annotations

import os
import re

from ..colour import COLOUR_SPACES, check_colour_space
from .axes import header_comments

_PREFIX = "gs_ibl colour_space"
_PATTERN = re.compile(rf"^{_PREFIX}=({'|'.join(COLOUR_SPACES)})\s*$")
DEFAULT_FOR_FILES = "srgb"  # what a file that declares nothing is taken to hold (Blender's rule)


def colour_space_comment(space: str) -> str:
    """The comment (without PLY's leading ``comment ``) declaring a file's colour space."""
    return f"{_PREFIX}={check_colour_space(space)}"


def declared_colour_space(path: str | os.PathLike) -> str | None:
    """The colour space a PLY file's header declares, or None (not a PLY, no declaration, unreadable)."""
    for text in header_comments(path):
        m = _PATTERN.match(text)
        if m:
            return m.group(1)
    return None


def resolve_colour_space(choice: str, path: str | os.PathLike | None) -> str:
    """The colour space to use: ``choice`` itself, or for "auto" what the file declares, else srgb."""
    if choice == "auto":
        return (declared_colour_space(path) if path is not None else None) or DEFAULT_FOR_FILES
    return check_colour_space(choice, "--colour-space")
