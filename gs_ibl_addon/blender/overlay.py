"""Viewport overlay: the splats, rendered by our renderer from each 3D View's camera, depth-tested against meshes.

A SpaceView3D POST_VIEW draw handler. Blender calls it after every engine and its own overlays (grid, wires,
extras) have drawn, with the scene's depth buffer bound. Per splat object it keeps one SplatOverlay over the
object's shared GPU renderer (splat_cache: uploaded once, shared with probe bakes, re-uploaded only when the
object moves or its mesh changes) and per viewport region the last image, re-rendered only when the view, the
region size or the resolution changed (overlay_math). While a view moves it is rendered at a quarter of the
resolution and refined by one timed redraw once the view has been still for SETTLE_S (overlay_math.ViewMotion).

The image is drawn as one quad by a shader of ours that turns the renderer's depth into fragment depth, so a mesh
in front of the splats hides them and splats in front of a mesh hide it, and applies exposure and the sRGB curve:
both per pixel on the GPU (in numpy they cost 0.3 s a frame at 1920x1080; overlay_math.to_display and window_depth
are the shader's reference, compared with it in a real Blender by tests/real_blender/gui_overlay.py). The textures
hold the renderer's linear premultiplied colour and distance as they come: changing Exposure uploads nothing.
While the overlay shows, splat objects draw nothing of their own (hide_helpers): Blender's lines and points
(loose vertices as black dots, bounds boxes) land on top of what a POST_VIEW handler draws, whatever its depth.
"""
from __future__ import annotations

import time
from collections import deque

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import splat_cache
from .overlay_math import DEPTH_PULL, SplatOverlay, ViewMotion, view_key
from .compat import get_modifier_input, modifier_input_identifiers, set_modifier_input
from .splat_object import PROXY_MODIFIER, is_mesh_splats, is_splat_object

HIDDEN_KEY = "gs_ibl_proxy_fraction"  # on a splat object while the overlay shows: its proxy's fraction to restore
ALPHA_CUT = 1.0 / 255.0  # fragments with less coverage are not drawn
OPAQUE_CUT = 0.5  # the depth pass writes the depth of pixels at least this covered

_handle = None
_overlays: dict[int, SplatOverlay] = {}  # splat_cache.uid(object) -> its images over the shared renderer
_textures: dict[tuple[int, int], tuple] = {}  # (object uid, region) -> (image, colour texture, depth texture)
_motion = ViewMotion()
_refine_scheduled = False
_shader = None
last_error: str | None = None
last_draw: dict = {}  # what the last draw did, per region (scale, render ms): read by tests and the GUI check
draw_log: deque = deque(maxlen=64)  # (time, region, scale, render ms) of recent draws, for the GUI check

_VERTEX = """
void main() {
  uv = texCoord;
  gl_Position = vec4(pos, 0.0, 1.0);
}
"""
# overlay_math.to_display and overlay_math.window_depth, per pixel: colour premultiplied by coverage, clipped at
# it, sRGB-encoded; distance along the view axis -> window depth through the viewport's projection (1: no splat).
_FRAGMENT = """
void main() {
  vec4 c = texture(image, uv);
  if (c.a < alpha_cut) {
    discard;
  }
  float a = clamp(c.a, 0.0, 1.0);
  vec3 col = clamp(c.rgb * exposure_scale, vec3(0.0), vec3(max(c.a, 0.0)));
  vec3 srgb = mix(1.055 * pow(col, vec3(1.0 / 2.4)) - 0.055, 12.92 * col, lessThanEqual(col, vec3(0.0031308)));
  fragColor = vec4(srgb, a);
  float d = texture(depth_image, uv).r;
  float z = -(d - depth_offset) * (1.0 - depth_pull);
  float w = depth_proj.z * z + depth_proj.w;
  float win = 0.5 * (depth_proj.x * z + depth_proj.y) / w + 0.5;
  gl_FragDepth = (d > 0.0 && w > 0.0 && win >= 0.0 && win <= 1.0) ? win : 1.0;
}
"""


def overlay_for(obj: bpy.types.Object) -> SplatOverlay:
    """The object's overlay: its images over the renderer splat_cache shares with bakes (new when that changes)."""
    splats = splat_cache.get(obj)
    ov = _overlays.get(splat_cache.uid(obj))
    if ov is not None and ov.renderer is splats.renderer:
        return ov
    if ov is not None:
        ov.close()  # its images only: the renderer belongs to splat_cache
    ov = SplatOverlay(renderer=splats.renderer)
    _overlays[splat_cache.uid(obj)] = ov
    return ov


def clear_cache() -> None:
    """Drop the overlay's images and textures (the uploaded splats stay in splat_cache for bakes)."""
    for ov in _overlays.values():
        ov.close()
    _overlays.clear()
    _textures.clear()


def splat_image(obj: bpy.types.Object, region_3d, width: int, height: int, scale: float, slot: object = 0):
    """The OverlayImage the handler would draw for ``obj`` in a view (works in background mode)."""
    return overlay_for(obj).image(np.array(region_3d.view_matrix), np.array(region_3d.window_matrix),
                                  width, height, scale, slot)


def _shader_get():
    """Our image shader: display colour and gl_FragDepth from the renderer's images (made once per session)."""
    global _shader
    if _shader is None:
        import gpu
        iface = gpu.types.GPUStageInterfaceInfo("gs_ibl_overlay_iface")
        iface.smooth("VEC2", "uv")
        info = gpu.types.GPUShaderCreateInfo()
        info.vertex_in(0, "VEC2", "pos")
        info.vertex_in(1, "VEC2", "texCoord")
        info.vertex_out(iface)
        info.sampler(0, "FLOAT_2D", "image")
        info.sampler(1, "FLOAT_2D", "depth_image")
        info.push_constant("FLOAT", "alpha_cut")
        info.push_constant("FLOAT", "exposure_scale")
        info.push_constant("VEC4", "depth_proj")  # window matrix P22, P23, P32, P33
        info.push_constant("FLOAT", "depth_offset")
        info.push_constant("FLOAT", "depth_pull")
        info.fragment_out(0, "VEC4", "fragColor")
        if hasattr(info, "depth_write"):  # Vulkan/Metal backends must be told; OpenGL needs no declaration
            info.depth_write("ANY")
        info.vertex_source(_VERTEX)
        info.fragment_source(_FRAGMENT)
        _shader = gpu.shader.create_from_info(info)
    return _shader


def _float_texture(px: np.ndarray, fmt: str):
    import gpu
    px = np.ascontiguousarray(px[::-1], np.float32)  # GPU rows go bottom-up
    h, w = px.shape[:2]
    return gpu.types.GPUTexture((w, h), format=fmt, data=gpu.types.Buffer("FLOAT", px.size, px.ravel()))


def shader_params(view, exposure: float, pull: float = DEPTH_PULL) -> tuple:
    """The shader's per-image uniforms: (exposure scale, (P22, P23, P32, P33), depth offset, pull)."""
    p = view.window_matrix
    return (float(2.0 ** exposure), (float(p[2, 2]), float(p[2, 3]), float(p[3, 2]), float(p[3, 3])),
            float(view.depth_offset), float(pull))


def textures(rgba: np.ndarray, depth: np.ndarray) -> tuple:
    """GPU textures of the renderer's premultiplied linear colour and its distance image (rows top first)."""
    return _float_texture(rgba, "RGBA32F"), _float_texture(depth, "R32F")


def _textures_for(key: tuple[int, int], img) -> tuple:
    cached = _textures.get(key)
    if cached is not None and cached[0] is img:  # identity: ids of freed images recur
        return cached[1], cached[2]
    colour, depth = textures(img.rgba, img.depth)
    _textures[key] = (img, colour, depth)
    return colour, depth


def draw_quads(quads: list[tuple]) -> None:
    """Two passes over the splat objects' images (colour texture, depth texture, NDC rectangle, shader_params),
    far first.

    The depth pass writes the depth of the well-covered pixels of every object, so in the colour pass an object
    is hidden where another one's splats are in front of it, whatever their order (a room drawn after a small
    capture inside it would otherwise cover it). The colour pass blends each image, premultiplied, where it is
    not behind a mesh or another object's splats; soft edges blend in the far-first order.
    """
    import gpu
    from gpu_extras.batch import batch_for_shader
    shader = _shader_get()
    batches = [batch_for_shader(shader, "TRI_FAN", {"pos": ((x0, y0), (x1, y0), (x1, y1), (x0, y1)),
                                                    "texCoord": ((0, 0), (1, 0), (1, 1), (0, 1))})
               for _c, _d, (x0, y0, x1, y1), _p in quads]
    saved = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get())
    gpu.state.depth_test_set("LESS_EQUAL")
    try:
        shader.bind()
        for colour_pass in (False, True):
            gpu.state.color_mask_set(colour_pass, colour_pass, colour_pass, colour_pass)
            gpu.state.depth_mask_set(not colour_pass)
            gpu.state.blend_set("ALPHA_PREMULT" if colour_pass else "NONE")
            shader.uniform_float("alpha_cut", ALPHA_CUT if colour_pass else OPAQUE_CUT)
            for (colour, depth, _rect, (k, proj, offset, pull)), batch in zip(quads, batches):
                shader.uniform_sampler("image", colour)
                shader.uniform_sampler("depth_image", depth)
                shader.uniform_float("exposure_scale", k)
                shader.uniform_float("depth_proj", proj)
                shader.uniform_float("depth_offset", offset)
                shader.uniform_float("depth_pull", pull)
                batch.draw(shader)
    finally:
        gpu.state.color_mask_set(True, True, True, True)
        gpu.state.depth_test_set(saved[0])
        gpu.state.depth_mask_set(saved[1])
        gpu.state.blend_set(saved[2])


def _forget_undrawn(slot: int, drawn: set[int]) -> None:
    """Free the textures of objects this region no longer draws, and the images of deleted splat objects (their
    renderers are freed by splat_cache); otherwise they would stay on the GPU until Show Splats is turned off."""
    for key in [k for k in _textures if k[1] == slot and k[0] not in drawn]:
        del _textures[key]
    if len(_overlays) > len(drawn):
        live = {splat_cache.uid(o) for o in bpy.data.objects if is_splat_object(o)}
        for uid in [u for u in _overlays if u not in live]:
            _overlays.pop(uid).close()


def draw_callback() -> None:
    global last_error
    context = bpy.context
    settings = getattr(context.scene, "gs_ibl_overlay", None)
    rv3d, region = context.region_data, context.region
    if settings is None or not settings.show or rv3d is None or region is None:
        return
    try:
        view, window = np.array(rv3d.view_matrix), np.array(rv3d.window_matrix)
        eye = np.linalg.inv(view)[:3, 3]
        objs = [o for o in context.visible_objects if is_mesh_splats(o)]  # Blender draws its native splats itself
        objs.sort(key=lambda o: -np.linalg.norm(np.array(o.matrix_world.translation) - eye))  # far first
        slot = region.as_pointer()
        now = time.monotonic()
        scale = _motion.scale(slot, view_key(view, window, region.width, region.height), now,
                              settings.resolution_scale)
        ms, quads = 0.0, []
        for obj in objs:
            img = splat_image(obj, rv3d, region.width, region.height, scale, slot)
            ms += img.render_ms
            quads.append((*_textures_for((splat_cache.uid(obj), slot), img), img.view.ndc_rect,
                          shader_params(img.view, settings.exposure)))
        if quads:
            draw_quads(quads)
        _forget_undrawn(slot, {splat_cache.uid(o) for o in objs})
        last_draw[slot] = {"scale": scale, "render_ms": ms, "objects": len(objs), "time": now}
        draw_log.append((now, slot, scale, ms))
        _schedule_refine(now)
        last_error = None
    except Exception as e:  # noqa: BLE001  a draw handler that raises would print on every redraw
        if str(e) != last_error:
            print(f"GS-IBL overlay: {e}")
        last_error = str(e)


def _schedule_refine(now: float) -> None:
    """One timer redraws the viewports when a region drawn coarse while moving has been still long enough."""
    global _refine_scheduled
    wait = _motion.refine_in(now)
    if wait is None or _refine_scheduled:
        return
    _refine_scheduled = True
    bpy.app.timers.register(_refine, first_interval=max(wait, 0.02))


def _refine() -> float | None:
    global _refine_scheduled
    wait = _motion.refine_in(time.monotonic())
    if wait is not None and wait > 0.0:
        return wait  # the view moved again meanwhile: wait for it to settle
    _refine_scheduled = False
    if wait is not None:
        tag_redraw()
    return None


def tag_redraw() -> None:
    wm = bpy.context.window_manager
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


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
    global _motion
    hide_helpers(settings.show)
    _motion = ViewMotion()  # views that changed while hidden are drawn at full resolution at once
    if not settings.show:
        clear_cache()
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


def register_overlay() -> None:
    global _handle
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")
    if _on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(_on_depsgraph_update)


def unregister_overlay() -> None:
    global _handle, _refine_scheduled, _shader
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    while _on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_on_depsgraph_update)
    if _refine_scheduled and bpy.app.timers.is_registered(_refine):
        bpy.app.timers.unregister(_refine)
    _refine_scheduled = False
    _shader = None
    clear_cache()
    try:
        hide_helpers(False)  # a disabled extension leaves the point proxies showing
    except (AttributeError, RuntimeError):  # data not accessible while Blender quits
        pass
