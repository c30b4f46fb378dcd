"""gs-ibl: light Blender meshes with the light of a 3D Gaussian Splatting scene.

This package is both the Blender extension (Blender calls register()/unregister()) and a plain Python
library (``gs_ibl_addon.core``, ``python -m gs_ibl_addon``). Blender's modules are imported only inside
register(), so importing the package never needs bpy.
"""
from __future__ import annotations


def register() -> None:
    try:
        import numpy  # noqa: F401
    except ImportError:
        # Official Blender builds bundle numpy; a Linux distribution's Blender uses the system's Python, where
        # numpy is a separate package that Debian's blender does not depend on. Too large to ship in our zip.
        raise ImportError("GS-IBL needs numpy, which this Blender's Python lacks: install it for that Python "
                          "(Debian/Ubuntu: sudo apt install python3-numpy), or use an official Blender build "
                          "from blender.org, which bundles it") from None
    from .blender import registration
    registration.register()


def unregister() -> None:
    from .blender import registration
    registration.unregister()
