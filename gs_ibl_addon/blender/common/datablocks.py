"""How the extension recognises its own datablocks: the custom property ``gs_ibl`` holding a role.

Names are the user's to change and to reuse (a user may have a World called "GS-IBL World"), so our images,
Worlds, node groups and materials are found by this marker, never by name; a datablock of the user's with the
same name is left alone and ours gets Blender's .001 suffix.
"""
from __future__ import annotations

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
