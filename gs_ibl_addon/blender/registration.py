"""Registers every Blender class, property, menu entry, handler and draw handler of the extension, and removes
them all again."""
from __future__ import annotations

import bpy

from ..core.vk import pipeline_cache
from .lighting import auto_update, undo
from .render import frame as render_frame
from .splats import cache as splat_cache
from .splats import importer, webp_decoder
from .splats import object as splat_object
from .ui import local_light_ui, panel, properties
from .viewport import overlay, picking

_CLASSES = (*properties.CLASSES, *importer.CLASSES, *panel.CLASSES, *local_light_ui.CLASSES)
_MENUS = (*importer.MENUS, *panel.MENUS)


def register() -> None:
    pipeline_cache.set_cache_dir_from(lambda: bpy.utils.extension_path_user(  # Blender 4.2+, as an extension only
        __package__.rpartition(".")[0], path="vulkan_cache", create=True))
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    properties.register_properties()
    for menu, fn in _MENUS:
        menu.append(fn)
    splat_cache.register_handlers()
    splat_object.register_handlers()
    auto_update.register_handlers()
    undo.register_handlers()
    render_frame.register_handlers()
    overlay.register_overlay()
    picking.register_picking()
    webp_decoder.register()


def unregister() -> None:
    webp_decoder.unregister()
    picking.unregister_picking()
    overlay.unregister_overlay()
    render_frame.unregister_handlers()
    undo.unregister_handlers()
    auto_update.unregister_handlers()
    splat_object.unregister_handlers()
    splat_cache.unregister_handlers()  # after the overlay: frees the renderers it drew with
    for menu, fn in reversed(_MENUS):
        menu.remove(fn)
    properties.unregister_properties()
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
