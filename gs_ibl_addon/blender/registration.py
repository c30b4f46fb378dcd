"""Registers every Blender class, property and menu entry of the extension, and removes them all again."""
from __future__ import annotations

import bpy

from . import importer, panel, properties

_CLASSES = (*properties.CLASSES, *importer.CLASSES, *panel.CLASSES)
_MENUS = (*importer.MENUS, *panel.MENUS)


def register() -> None:
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    properties.register_properties()
    for menu, fn in _MENUS:
        menu.append(fn)


def unregister() -> None:
    for menu, fn in reversed(_MENUS):
        menu.remove(fn)
    properties.unregister_properties()
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
