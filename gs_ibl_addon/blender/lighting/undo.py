"""Undo and redo of bakes: the World's light, the probe and its report come back together, and nothing re-bakes.

Blender's undo restores the datablocks; the stamps (stamps.py) bring back the pixels they name, the splats' GPU
copy is checked against the restored objects, and Update When Moved takes the restored places as baked
(auto_update.rebaseline_after_undo).
"""
from __future__ import annotations

from bpy.app.handlers import persistent

from ..common import handlers
from ..splats import cache as splat_cache
from . import stamps
from .auto_update import rebaseline_after_undo


@persistent
def on_undo_redo(*_args) -> None:
    splat_cache.undo_restored()
    stamps.restore_pixels()
    rebaseline_after_undo()


@persistent
def on_load_pre(*_args) -> None:
    stamps.forget()  # another file's images


_HANDLERS = (("undo_post", on_undo_redo), ("redo_post", on_undo_redo), ("load_pre", on_load_pre))


def register_handlers() -> None:
    handlers.add(_HANDLERS)


def unregister_handlers() -> None:
    handlers.remove(_HANDLERS)
    stamps.forget()
