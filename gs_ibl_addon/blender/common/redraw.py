"""Asking every 3D View to draw again: after a job's result lands, or when the overlay has a new image."""
from __future__ import annotations

import bpy


def tag_redraw() -> None:
    wm = bpy.context.window_manager
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
