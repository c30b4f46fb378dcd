"""gs-ibl: light Blender meshes with the light of a 3D Gaussian Splatting scene.

This package is both the Blender extension (Blender calls register()/unregister()) and a plain Python
library (``gs_ibl_addon.core``, ``python -m gs_ibl_addon``). Blender's modules are imported only inside
register(), so importing the package never needs bpy.
"""
from __future__ import annotations


def register() -> None:
    from .blender import registration
    registration.register()


def unregister() -> None:
    from .blender import registration
    registration.unregister()
