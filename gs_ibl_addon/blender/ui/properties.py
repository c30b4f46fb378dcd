"""Probe settings, stored on the probe Empty (Object.gs_ibl_probe), saved with the .blend and undoable."""
from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, IntVectorProperty, PointerProperty,
                       StringProperty)

from ...core.settings import (DEFAULT_IRRADIANCE_SIZE, DEFAULT_METHOD, DEFAULT_TOLERANCE, MAX_FACE_SIZE,
                             MAX_IRRADIANCE_SIZE, MAX_TOLERANCE, MIN_TOLERANCE, blender_colour_space_items,
                             blender_method_items)
from ..splats.object import is_splat_object

def _poll_splats(_self, obj) -> bool:
    return is_splat_object(obj)


def _strength_changed(self, context) -> None:
    # Live: the World, lights and meshes this probe baked follow the slider without a re-bake (lighting/bake.py)
    from ..lighting.bake import apply_strength
    probe = self.id_data
    scene = getattr(context, "scene", None)
    if isinstance(probe, bpy.types.Object) and scene is not None:
        apply_strength(scene, probe)


def _keep_background_changed(self, context) -> None:
    # At once: the World is made again from the images of the last bake (no re-bake; lighting/bake.py)
    from ..lighting.bake import rebuild_world
    probe = self.id_data
    scene = getattr(context, "scene", None)
    if isinstance(probe, bpy.types.Object) and scene is not None:
        rebuild_world(scene, probe)


def _lighting_changed(_self, context) -> None:
    # The bake no longer says how meshes are lit: the status bar marks it out of date now (lighting/stale.py), not
    # at the next depsgraph update (a settings edit may bring none)
    from ..lighting.stale import refresh_notice
    scene = getattr(context, "scene", None)
    if scene is not None:
        refresh_notice(scene)


class GSIBL_ProbeSettings(bpy.types.PropertyGroup):
    is_probe: BoolProperty(default=False, options={"HIDDEN"})
    splats: PointerProperty(name="Splats", type=bpy.types.Object, poll=_poll_splats,
                            description="Splat object whose light this probe captures")
    method: EnumProperty(
        name="Method",
        items=blender_method_items(),  # core/settings.py: the one list of methods
        default=DEFAULT_METHOD.upper())
    face_size: IntProperty(name="Face Size", default=0, min=0, max=MAX_FACE_SIZE,
                           description="Resolution of each of the six radiance faces rendered from the probe "
                                       "(0: the smallest estimated to meet the tolerance)")
    irradiance_size: IntProperty(name="Irradiance Size", default=DEFAULT_IRRADIANCE_SIZE, min=4,
                                 max=MAX_IRRADIANCE_SIZE,
                                 description="Face size of the irradiance cube; its lat-long image is 4x as wide "
                                             "and 2x as high")
    tolerance: FloatProperty(name="Tolerance", default=DEFAULT_TOLERANCE, min=MIN_TOLERANCE, max=MAX_TOLERANCE,
                             precision=3,
                             description="Relative RMS irradiance error allowed: with Face Size 0 the face size is "
                                         "chosen from an error estimate to meet it (the report gives the estimate)")
    lights: IntProperty(name="Lights", default=0, min=0, max=8,
                        description="Split up to this many bright compact regions (sun, lamp, window) off the probe "
                                    "as sun lights with shadows; the World keeps the rest")
    highlight_gain: FloatProperty(name="Highlight Gain", default=1.0, min=1.0, soft_max=100.0,
                                  description="Directions clipped at the top of the range (windows and lamps in a "
                                              "capture trained on 8-bit photos) times this: the light's real "
                                              "brightness over 1.0")
    strength: FloatProperty(name="Strength", default=1.0, min=0.0, soft_max=10.0, update=_strength_changed,
                            description="Multiplier of the probe's light in the World")
    keep_background: BoolProperty(name="Keep Background", default=True, update=_keep_background_changed,
                                  description="Camera rays see the previous World; only lighting comes from the "
                                              "probe. Takes effect at once (the World is made again from the last "
                                              "bake's images)")
    assign_world: BoolProperty(name="Use as Scene World", default=True,
                               description="Make the GS-IBL World the scene's World after baking (the previous one "
                                           "is remembered and can be restored)")
    mute_native_splats: BoolProperty(
        name="Native Splats Light Once", default=True,
        description="Blender 5.3's native splats stop lighting meshes through Cycles' bounces and casting shadows "
                    "while the baked World carries their light (it would count twice, and their shadows would darken "
                    "it); the camera still sees them. Restore Previous World gives them back")
    pack_images: BoolProperty(name="Pack Images", default=True,
                              description="Keep baked images inside the .blend; off: save EXR files next to it")
    auto_update: BoolProperty(name="Update When Moved", default=False,
                              description="Re-bake once after the probe or its splat object was moved")
    update_interval: FloatProperty(name="Update Delay", default=0.5, min=0.0, soft_max=10.0, unit="TIME_ABSOLUTE",
                                   description="Seconds the probe and its splats must stay still before the "
                                               "automatic re-bake (a drag bakes once, at its end)")
    lighting: EnumProperty(
        name="Lighting", default="AUTO", update=_lighting_changed,
        items=[("AUTO", "Auto", "Each lit mesh (inside the splats' bounds) gets the light it needs, measured at every "
                "bake and when it moves: this probe's World, a probe of its own, or a grid over it"),
               ("VOLUME", "Volume", "One light volume over the region every lit mesh occupies over the frame "
                "range, shared by all of them and read where each one stands (moving meshes included, no re-bake); "
                "a mesh outside it keeps this probe's World"),
               ("WORLD", "World Probe", "Every mesh is lit by this probe through the World; per-object probes and "
                "grids only where asked (More Than One Probe)")],
        description="How lit meshes get their diffuse light")
    volume_probes: IntProperty(
        name="Volume Probes", default=512, min=64, soft_max=4096, max=16384, update=_lighting_changed,
        description="Lighting Volume: the most probes its bake renders (a grid over the lit meshes with 60% of them, "
                    "finer bricks where the light changes with the rest); more follow the light more closely and "
                    "take longer (on a CPU about 0.05-0.1 s a probe, on a GPU well under 1 ms)")
    # More than one probe (blender/object_probes.py, probe_grid.py, auto_light.py)
    variation_tolerance: FloatProperty(name="Variation Tolerance", default=0.05, min=0.005, max=1.0, precision=3,
                                       subtype="FACTOR",
                                       description="Check Light Variation warns about a mesh whose irradiance at "
                                                   "its bounding-box corners differs more than this from its centre")
    grid_region: PointerProperty(name="Grid Region", type=bpy.types.Object,
                                 description="An Empty whose box (Cube display, its size and scale) the probe grid "
                                             "spans; none: the lit meshes' bounds")
    grid_resolution: IntVectorProperty(name="Grid", size=3, default=(3, 3, 2), min=1, max=16,
                                       description="Probes along X, Y and Z of the probe grid")
    local_report: StringProperty(name="Local Light", default="", options={"HIDDEN"})
    # Shown after a bake (read-only in the panel): what the last bake did.
    last_report: StringProperty(name="Last Bake", default="", options={"HIDDEN"})
    # The report in one line (time, face size, estimated error, how meshes are lit): what the panel shows, with the
    # report one click away (WindowManager.gs_ibl_report_details). Empty in files baked before it existed.
    last_summary: StringProperty(name="Last Bake Summary", default="", options={"HIDDEN"})
    # What the last bake of this probe wrote: re-bakes update these in place, Strength edits this World only.
    world: PointerProperty(type=bpy.types.World, options={"HIDDEN"})
    radiance_image: PointerProperty(type=bpy.types.Image, options={"HIDDEN"})
    irradiance_image: PointerProperty(type=bpy.types.Image, options={"HIDDEN"})


def _overlay_shown(self, context) -> None:
    from ..viewport import overlay
    overlay.show_changed(self, context)


def _overlay_display(self, context) -> None:
    # Display-only: a redraw, never a re-read or re-upload of the splats.
    from ..viewport import overlay
    overlay.display_changed(self, context)


class GSIBL_OverlaySettings(bpy.types.PropertyGroup):
    show: BoolProperty(name="Show Splats", default=False, update=_overlay_shown,
                       description="Draw the splats (rendered by GS-IBL's renderer from the view) in 3D Viewports, "
                                   "in front of or behind meshes by depth; meanwhile splat objects draw no point "
                                   "proxy of their own. Not part of F12 renders")
    resolution_scale: FloatProperty(name="Resolution", default=0.5, min=0.1, max=1.0, subtype="FACTOR",
                                    update=_overlay_display,
                                    description="Fraction of the viewport's resolution the splats are rendered at "
                                                "once the view is still (a quarter while it moves)")
    exposure: FloatProperty(name="Exposure", default=0.0, soft_min=-10.0, soft_max=10.0, update=_overlay_display,
                            description="Stops of brightness applied to the splats in the viewport only")


class GSIBL_SplatSettings(bpy.types.PropertyGroup):
    """Settings of a splat object (ours or a Blender 5.3 Gaussian-splat Point Cloud)."""
    colour_space: EnumProperty(
        name="Colour Space",
        items=blender_colour_space_items(),  # core/settings.py: the one vocabulary
        default="SRGB",  # Blender's rule; our importer sets what the file declares
        update=_overlay_display,  # the overlay redraws; bakes read it when they run
        description="What the splats' colours mean, for probe bakes and the overlay")


def _render_setting_changed(self, context) -> None:
    # The compositor nodes and images go in or out at once (render/setup.py), on the main thread
    from ..render import setup
    if isinstance(self.id_data, bpy.types.Scene):
        setup.enabled_changed(self.id_data)


def _get_transparent(self) -> bool:
    from ..render import compositor
    return compositor.transparent(self.id_data)


def _set_transparent(self, value: bool) -> None:
    from ..render import compositor
    compositor.set_transparent(self.id_data, value)


class GSIBL_RenderSettings(bpy.types.PropertyGroup):
    """Splats in final renders (F12, Render Animation, blender -b -f/-a), per scene (render/)."""
    enabled: BoolProperty(name="Splats in Renders", default=True, update=_render_setting_changed,
                          description="Draw the splat objects whose camera icon is on into F12 renders and "
                                      "animations, in front of and behind meshes by depth, through nodes added to "
                                      "the compositor (Film Transparent is turned on); off takes the nodes out "
                                      "again and restores the settings")
    write_pass: BoolProperty(name="Splat Pass File", default=False, update=_render_setting_changed,
                             description="Also write the splats in front of and behind the meshes as layers "
                                         "'front' and 'behind' of a multilayer EXR per frame (a File Output node), "
                                         "for compositing elsewhere")
    pass_path: StringProperty(name="Splat Pass Folder", default="//splat_pass/", subtype="DIR_PATH",
                              update=_render_setting_changed,
                              description="Where the Splat Pass File is written (splats_<view layer>_<frame>.exr)")
    transparent: BoolProperty(name="Transparent", get=_get_transparent, set=_set_transparent,
                              description="Your Film Transparent: off, the World shows behind meshes and splats "
                                          "(Blender's Film Transparent stays on while splats are in renders, and "
                                          "the World is put back from the Environment pass); on, the background "
                                          "is transparent")
    shadows: BoolProperty(name="Shadows on Splats", default=True,
                          description="Meshes darken the splats under them (shadows and contact darkening), lit "
                                      "from the baked probe whose World the scene uses; the same in Cycles and "
                                      "EEVEE. Needs a baked probe")
    native_splats: EnumProperty(
        name="Native Splats", default="GSIBL", update=_render_setting_changed,
        items=(("BLENDER", "Blender", "Cycles or EEVEE renders Blender's Gaussian-splat objects itself: seen in "
                "reflections, casting Cycles shadows, at many times the time per frame and with sampling noise"),
               ("GSIBL", "GS-IBL", "GS-IBL draws Blender's Gaussian-splat objects with the other splats, by depth "
                "with the meshes, as 3D Gaussian Splatting's viewers show them; Blender leaves them out of that "
                "render (the objects are not changed)")),
        description="Who draws Blender 5.3's own Gaussian-splat objects in F12 renders")
    shadow_strength: FloatProperty(name="Shadow Strength", default=1.0, min=0.0, max=1.0, subtype="FACTOR",
                                   description="How much of the light the meshes block is taken from the splats "
                                               "(1: all of it, as a path tracer would)")


CLASSES = (GSIBL_ProbeSettings, GSIBL_OverlaySettings, GSIBL_SplatSettings, GSIBL_RenderSettings)


def register_properties() -> None:
    bpy.types.Object.gs_ibl_probe = PointerProperty(type=GSIBL_ProbeSettings)
    bpy.types.Scene.gs_ibl_overlay = PointerProperty(type=GSIBL_OverlaySettings)
    bpy.types.Object.gs_ibl_splats = PointerProperty(type=GSIBL_SplatSettings)
    bpy.types.Scene.gs_ibl_render = PointerProperty(type=GSIBL_RenderSettings)
    # UI state only: on the window manager, whose edits are no undo steps and which no scene or probe carries
    bpy.types.WindowManager.gs_ibl_report_details = BoolProperty(
        name="Details", default=False,
        description="Show the last bake's whole report (what it did, the face-size search, how long each part "
                    "took), not only its summary line")


def unregister_properties() -> None:
    del bpy.types.WindowManager.gs_ibl_report_details
    del bpy.types.Scene.gs_ibl_render
    del bpy.types.Object.gs_ibl_splats
    del bpy.types.Scene.gs_ibl_overlay
    del bpy.types.Object.gs_ibl_probe
