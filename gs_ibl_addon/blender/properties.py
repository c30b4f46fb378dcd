"""Probe settings, stored on the probe Empty (Object.gs_ibl_probe), saved with the .blend and undoable."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from .splat_object import is_splat_object

PROBE_NAME = "GS-IBL Probe"


def is_probe(obj: bpy.types.Object | None) -> bool:
    return obj is not None and obj.type == "EMPTY" and obj.gs_ibl_probe.is_probe


def _poll_splats(_self, obj) -> bool:
    return is_splat_object(obj)


def _strength_changed(self, context) -> None:
    # Live: the World's strength node follows the slider without a re-bake.
    from .world import MARKER, set_world_strength
    for w in bpy.data.worlds:
        if w.get(MARKER) == "world":
            set_world_strength(w, self.strength)


class GSIBL_ProbeSettings(bpy.types.PropertyGroup):
    is_probe: BoolProperty(default=False, options={"HIDDEN"})
    splats: PointerProperty(name="Splats", type=bpy.types.Object, poll=_poll_splats,
                            description="Splat object whose light this probe captures")
    method: EnumProperty(
        name="Method",
        items=[("AUTO", "Auto", "Choose from the tolerance: SH projection when it is accurate enough, else convolution"),
               ("SH", "Spherical Harmonics", "Project the radiance onto 9 SH coefficients (fast, smooth)"),
               ("CONV", "Cosine Convolution", "Exact cosine-weighted integral per irradiance texel"),
               ("BOX", "Box Filter", "Box-filtered mip chain (fast approximation)")],
        default="AUTO")
    face_size: IntProperty(name="Face Size", default=64, min=4, max=2048,
                           description="Resolution of each of the six radiance faces rendered from the probe")
    irradiance_size: IntProperty(name="Irradiance Size", default=32, min=4, max=1024,
                                 description="Height of the irradiance lat-long map (its width is twice that)")
    tolerance: FloatProperty(name="Tolerance", default=0.01, min=1e-4, max=0.5, precision=3,
                             description="Relative irradiance error allowed when choosing sizes and method")
    strength: FloatProperty(name="Strength", default=1.0, min=0.0, soft_max=10.0, update=_strength_changed,
                            description="Multiplier of the probe's light in the World")
    keep_background: BoolProperty(name="Keep Background", default=True,
                                  description="Camera rays see the previous World; only lighting comes from the probe")
    assign_world: BoolProperty(name="Use as Scene World", default=True,
                               description="Make the GS-IBL World the scene's World after baking (the previous one "
                                           "is remembered and can be restored)")
    pack_images: BoolProperty(name="Pack Images", default=True,
                              description="Keep baked images inside the .blend; off: save EXR files next to it")


CLASSES = (GSIBL_ProbeSettings,)


def register_properties() -> None:
    bpy.types.Object.gs_ibl_probe = PointerProperty(type=GSIBL_ProbeSettings)


def unregister_properties() -> None:
    del bpy.types.Object.gs_ibl_probe
