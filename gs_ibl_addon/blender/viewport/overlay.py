"""Viewport overlay: the splats, rendered by our renderer from each 3D View's camera, depth-tested against meshes.

A SpaceView3D POST_VIEW draw handler (draw_callback). Blender calls it after every engine and its own overlays
(grid, wires, extras) have drawn, with the scene's depth buffer bound. Per splat object and region it draws the
image overlay_images hands it (rendered again only when the view, the region size or the resolution changed; a
quarter of the resolution while the view moves, refined once it has been still for SETTLE_S; a slow frame, an
upload or a busy GPU are left to a worker and the region's last image is drawn meanwhile).

The splats are drawn into Blender's overlay layer by one pass of a shader of ours (overlay_gpu; overlay_math.composite
is its numpy reference): it reads back what Blender drew there and the scene depth, turns the renderer's depth into
window depth and composites up to MAX_LAYERS splat objects per pixel, nearest first. So a mesh in front of the splats
hides them and splats in front of a mesh hide it; a mesh edge keeps its anti-aliasing; the floor grid never shows
through splats; the 3D cursor and object origins stay on top of them (overlay_discs). On llvmpipe (1311x878 region,
2 cores) a redraw of a still view costs the overlay ~170 ms after Blender's own drawing, against ~100 ms for the
plain depth-tested quads (draw_quads) that more objects than MAX_LAYERS fall back to.
While the overlay shows, splat objects draw nothing of their own (hide_helpers): Blender's lines and points
(loose vertices as black dots, bounds boxes) would show over the splats. picking.py puts the 3D cursor on the
splats and selects splat objects by clicking them, from the images drawn here (splats_under_mouse).
"""
from __future__ import annotations

import math
import time
from collections import deque

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..common import handlers
from ..common.compat import get_modifier_input, modifier_input_identifiers, set_modifier_input
from ..common.redraw import tag_redraw
from ..splats import cache as splat_cache
from ..splats.object import PROXY_MODIFIER, is_mesh_splats, is_splat_object
from . import overlay_gpu, overlay_images
from .overlay_gpu import MAX_DISCS, OPAQUE_CUT
from ...core.colour import srgb_to_linear
from .overlay_math import BACKGROUND_KINDS, MAX_LAYERS, splat_hit, view_key

HIDDEN_KEY = "gs_ibl_proxy_fraction"  # on a splat object while the overlay shows: its proxy's fraction to restore
_handle = None
_refine_scheduled = False
last_error: str | None = None
last_draw: dict = {}  # what the last draw did, per region (scale, render ms): read by tests and the GUI check
draw_log: deque = deque(maxlen=64)  # (time, region, scale, render ms, draw ms) of recent draws, for the GUI check
capture: dict = {}  # set capture["next"] = True: the next composite keeps its inputs and output (the GUI check)
use_composite = True  # False: the plain depth-tested quads only (the GUI check compares the two)


def viewport_background(context) -> dict:
    """How Blender's overlay fills this 3D View's background (overlay_background.hh): kind (overlay_math
    .BACKGROUND_KINDS), high and low linear colours, and whether the overlay layer holds it (Solid and Wireframe
    shading; Material Preview and Rendered draw their World into the render instead) so a pixel's render coverage
    can be read from it (its blue channel: not for backgrounds with almost no blue)."""
    shading = context.space_data.shading
    scene = context.scene
    if shading.type in {"WIREFRAME", "SOLID"}:
        if shading.background_type == "WORLD" and scene.world is not None:
            high = low = tuple(scene.world.color)
            kind = "SINGLE_COLOR"
        elif shading.background_type == "VIEWPORT":
            high = low = tuple(shading.background_color)
            kind = "SINGLE_COLOR"
        else:
            g = context.preferences.themes[0].view_3d.space.gradients
            high = tuple(srgb_to_linear(np.array(g.high_gradient)))
            low = tuple(srgb_to_linear(np.array(g.gradient)))
            kind = g.background_type if g.background_type in BACKGROUND_KINDS else "SINGLE_COLOR"
        blues = (high[2], low[2])
        use = min(blues) >= max(1.0 / 255.0, 0.25 * max(*high, *low))
        return {"kind": kind, "high": high, "low": low, "use_coverage": use}
    return {"kind": "SINGLE_COLOR", "high": (0.0, 0.0, 0.0), "low": (0.0, 0.0, 0.0), "use_coverage": False}


def grid_normal(space, rv3d):
    """The plane Blender draws its grid in and writes the depth of (through the origin): the floor in perspective
    and free orthographic views, the view plane in an axis-aligned orthographic view; None when it is not drawn."""
    ov = space.overlay
    if not ov.show_overlays:
        return None
    if not rv3d.is_perspective and rv3d.is_orthographic_side_view:
        if not ov.show_ortho_grid:
            return None
        return tuple(np.array(rv3d.view_matrix)[2, :3])
    return (0.0, 0.0, 1.0) if ov.show_floor else None


_PAINT_MODES = {"PAINT_WEIGHT", "PAINT_VERTEX", "PAINT_TEXTURE", "SCULPT", "SCULPT_CURVES", "PAINT_GPENCIL",
                "PAINT_GREASE_PENCIL", "WEIGHT_GPENCIL", "VERTEX_GPENCIL", "SCULPT_GPENCIL", "WEIGHT_GREASE_PENCIL",
                "VERTEX_GREASE_PENCIL", "SCULPT_GREASE_PENCIL"}


def _region_pixel(persmat: np.ndarray, width: int, height: int, point):
    clip = persmat @ np.array([*point, 1.0])
    if clip[3] <= 1e-9:
        return None
    return ((clip[0] / clip[3] + 1.0) * 0.5 * width, (clip[1] / clip[3] + 1.0) * 0.5 * height)


def overlay_discs(context, rv3d, width: int, height: int) -> list[tuple[float, float, float]]:
    """Where Blender draws the 3D cursor and the object origins in this region, (x, y, r) in region pixels: the
    composite keeps what Blender drew there on top of the splats. The cursor: a circle of half a widget unit and
    axis lines of one (overlay_cursor.hh), at its pixel; origins: dots of the theme's size, of the active and
    selected objects (all objects with Origins (All))."""
    ov = context.space_data.overlay
    if not ov.show_overlays or context.mode in _PAINT_MODES:
        return []
    prefs = context.preferences
    pixel = float(prefs.system.pixel_size)
    persmat = np.array(rv3d.window_matrix) @ np.array(rv3d.view_matrix)
    discs = []
    if ov.show_cursor:
        widget = round(18.0 * prefs.system.ui_scale) + 2.0 * pixel  # U.widget_unit
        xy = _region_pixel(persmat, width, height, context.scene.cursor.location)
        if xy is not None:
            discs.append((math.floor(xy[0]) + 0.5, math.floor(xy[1]) + 0.5, widget + 2.0 * pixel))
    if ov.show_object_origins:
        active = context.view_layer.objects.active
        r = 0.5 * (prefs.themes[0].view_3d.object_origin_size + 1.0) * pixel + 1.5
        for obj in context.visible_objects:
            if obj == active or obj.select_get() or ov.show_object_origins_all:
                xy = _region_pixel(persmat, width, height, obj.matrix_world.translation)
                if xy is not None:
                    discs.append((xy[0], xy[1], r))
    return [d for d in discs if -d[2] <= d[0] <= width + d[2] and -d[2] <= d[1] <= height + d[2]][:MAX_DISCS]


def _composite(context, rv3d, region, quads: list, settings, names=()) -> bool:
    """Draw the splat images with the composite shader; False when it cannot (too many objects, or their images
    land differently): the caller draws the plain quads."""
    if len(quads) > MAX_LAYERS or any(q[2] != quads[0][2] or q[3] != quads[0][3] for q in quads):
        return False
    w, h = region.width, region.height
    t0 = time.perf_counter()
    snap, depth, colour_buf, depth_buf = overlay_gpu._snapshot(w, h)
    t1 = time.perf_counter()
    params = overlay_gpu.composite_params(rv3d.window_matrix, rv3d.view_matrix, w, h, viewport_background(context),
                              grid_normal(context.space_data, rv3d), overlay_discs(context, rv3d, w, h))
    layers = [(q[0], q[1]) for q in quads]
    overlay_gpu.draw_composite(snap, depth, layers, quads[0][2], quads[0][3], params)
    overlay_gpu.timing.update(snapshot_ms=(t1 - t0) * 1e3, composite_ms=(time.perf_counter() - t1) * 1e3)
    if capture.pop("next", False):
        import gpu
        out = gpu.state.active_framebuffer_get().read_color(0, 0, w, h, 4, 0, "UBYTE")
        capture.update(size=(w, h), colour=np.frombuffer(colour_buf, np.uint8).reshape(h, w, 4).copy(),
                       depth=np.frombuffer(depth_buf, np.float32).reshape(h, w).copy(),
                       out=np.frombuffer(out, np.uint8).reshape(h, w, 4).copy(), params=params,
                       shading=quads[0][3], time=time.monotonic(), objects=list(names))
    return True


def draw_callback() -> None:
    global last_error
    context = bpy.context
    settings = getattr(context.scene, "gs_ibl_overlay", None)
    rv3d, region = context.region_data, context.region
    if settings is None or not settings.show or rv3d is None or region is None:
        return
    try:
        t0 = time.perf_counter()
        view, window = np.array(rv3d.view_matrix), np.array(rv3d.window_matrix)
        eye = np.linalg.inv(view)[:3, 3]
        objs = [o for o in context.visible_objects if is_mesh_splats(o)]  # Blender draws its native splats itself
        objs.sort(key=lambda o: -np.linalg.norm(np.array(o.matrix_world.translation) - eye))  # far first
        slot = region.as_pointer()
        now = time.monotonic()
        scale = overlay_images.motion.scale(slot, view_key(view, window, region.width, region.height), now,
                                            settings.resolution_scale)
        ms, quads = 0.0, []
        for obj in objs:
            img = overlay_images.image_now(obj, rv3d, region.width, region.height, scale, slot)
            if img is None:  # its splats are still being uploaded: nothing drawn of it yet
                continue
            ms += img.render_ms
            quads.append((*overlay_images.textures_for((splat_cache.uid(obj), slot), img), img.view.ndc_rect,
                          overlay_gpu.shader_params(img.view, settings.exposure)))
        composited = bool(quads) and use_composite and _composite(context, rv3d, region, quads, settings,
                                                                  [o.name for o in objs])
        if quads and not composited:
            overlay_gpu.draw_quads(quads)
        overlay_images.forget_undrawn(slot, {splat_cache.uid(o) for o in objs})
        draw_ms = (time.perf_counter() - t0) * 1e3
        last_draw[slot] = {"scale": scale, "render_ms": ms, "draw_ms": draw_ms, "objects": len(objs), "time": now,
                           "composited": composited, "objects_drawn": [o.name for o in objs]}
        draw_log.append((now, slot, scale, ms, draw_ms))
        _schedule_refine(now)
        last_error = None
        overlay_images.upload_error = None  # drawn: an earlier upload failure is over
    except Exception as e:  # noqa: BLE001  a draw handler that raises would print on every redraw
        if str(e) != last_error:
            print(f"GS-IBL overlay: {e}")
        last_error = str(e)


def error_text() -> str | None:
    """Why the splats are not drawn (the last draw's or upload's error), for the panel; None when they are."""
    return last_error or overlay_images.upload_error


def last_images(context, region, rv3d) -> list[tuple]:
    """(object, OverlayImage) of the splat objects drawn in this region, as last drawn there (rendered again if the
    view changed since): what the mouse points at."""
    settings = context.scene.gs_ibl_overlay
    slot = region.as_pointer()
    scale = last_draw.get(slot, {}).get("scale", settings.resolution_scale)
    images = [(o, overlay_images.image_now(o, rv3d, region.width, region.height, scale, slot, wait=True))
              for o in context.visible_objects if is_mesh_splats(o)]
    return [(o, img) for o, img in images if img is not None]


def splats_under_mouse(context, x: float, y: float):
    """The nearest splat object whose overlay image covers region pixel (x, y), with the hit (overlay_math
    .SplatHit), or None (Show Splats off, no splats there)."""
    settings = getattr(context.scene, "gs_ibl_overlay", None)
    region, rv3d = context.region, context.region_data
    if settings is None or not settings.show or region is None or rv3d is None:
        return None
    view, window = np.array(rv3d.view_matrix), np.array(rv3d.window_matrix)
    best = None
    for obj, img in last_images(context, region, rv3d):
        hit = splat_hit(img, view, window, region.width, region.height, x, y, OPAQUE_CUT)
        if hit is not None and (best is None or hit.distance < best[1].distance):
            best = (obj, hit)
    return best


def _schedule_refine(now: float) -> None:
    """One timer redraws the viewports when a region drawn coarse while moving has been still long enough."""
    global _refine_scheduled
    wait = overlay_images.motion.refine_in(now)
    if wait is None or _refine_scheduled:
        return
    _refine_scheduled = True
    bpy.app.timers.register(_refine, first_interval=max(wait, 0.02))


def _refine() -> float | None:
    global _refine_scheduled
    wait = overlay_images.motion.refine_in(time.monotonic())
    if wait is not None and wait > 0.0:
        return wait  # the view moved again meanwhile: wait for it to settle
    _refine_scheduled = False
    if wait is not None:
        tag_redraw()
    return None


def hide_helpers(show: bool) -> int:
    """While the overlay shows, splat objects draw nothing of their own; afterwards their point proxy is back.

    In Blender 5.x the lines and points of its overlays (an object's bounds, the black dots of a mesh's loose
    vertices) are drawn over POST_VIEW drawing whatever its depth, so a display type cannot hide them: the proxy's
    Fraction goes to 0 instead (no points, and the mesh's own vertices are not drawn while the modifier replaces
    them). The previous fraction is kept on the object. splat_cache is told that the geometry update Blender
    reports for this is not an edit, so nothing is uploaded again. Returns how many objects changed.
    """
    changed = 0
    for obj in bpy.data.objects:
        if obj.library is not None or (HIDDEN_KEY in obj.keys()) == show:
            continue  # linked (not ours to edit), or already as wanted: the depsgraph handler calls this often
        mod = obj.modifiers.get(PROXY_MODIFIER) if is_splat_object(obj) else None
        if mod is None or mod.node_group is None:
            continue
        fraction = modifier_input_identifiers(mod.node_group).get("Fraction")
        if fraction is None:
            continue
        if show and HIDDEN_KEY not in obj.keys():
            obj[HIDDEN_KEY] = float(get_modifier_input(mod, fraction))
            set_modifier_input(mod, fraction, 0.0)
        elif not show and HIDDEN_KEY in obj.keys():
            set_modifier_input(mod, fraction, float(obj[HIDDEN_KEY]))
            del obj[HIDDEN_KEY]
        else:
            continue
        splat_cache.proxy_switched(obj)
        changed += 1
    return changed


def show_changed(settings, context) -> None:
    """Show Splats toggled: helpers hidden or restored, images freed when off (the uploaded splats stay)."""
    hide_helpers(settings.show)
    overlay_images.reset_motion()
    if not settings.show:
        overlay_images.clear_cache()
    tag_redraw()


def display_changed(settings, context) -> None:
    """Resolution or Exposure changed: only the image is redrawn (the texture follows the exposure)."""
    tag_redraw()


@persistent
def _on_depsgraph_update(scene, depsgraph) -> None:
    # A splat object imported or appended while the overlay shows is hidden like the others.
    settings = getattr(scene, "gs_ibl_overlay", None)
    if settings is not None and settings.show:
        hide_helpers(True)


_HANDLERS = (("depsgraph_update_post", _on_depsgraph_update),)


def register_overlay() -> None:
    """The draw handler and the depsgraph handler (picking.py registers the click operators)."""
    global _handle
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")
    handlers.add(_HANDLERS)


def unregister_overlay() -> None:
    global _handle, _refine_scheduled
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    handlers.remove(_HANDLERS)
    if _refine_scheduled and bpy.app.timers.is_registered(_refine):
        bpy.app.timers.unregister(_refine)
    _refine_scheduled = False
    overlay_gpu.free()
    overlay_images.clear_cache()
    try:
        hide_helpers(False)  # a disabled extension leaves the point proxies showing
    except (AttributeError, RuntimeError):  # data not accessible while Blender quits
        pass
