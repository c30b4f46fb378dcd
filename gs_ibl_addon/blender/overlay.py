"""Viewport overlay: the splats, rendered by our renderer from each 3D View's camera, drawn behind the meshes.

A SpaceView3D POST_VIEW draw handler. Per splat object it keeps one SplatOverlay over the object's shared GPU
renderer (splat_cache: uploaded once, shared with probe bakes, re-uploaded when the object moves or its mesh
changes) and per viewport region the last image, re-rendered only when the view or window matrix, the region
size or the resolution changed (overlay_math.SplatOverlay). The image becomes a float GPUTexture drawn as one quad.

Depth: our renderer returns colour and coverage, no depth, so the quad is drawn at the far plane with the
depth test on: meshes always cover the splats (right for meshes inside a captured room; a splat object in
front of a mesh is hidden behind it). The logic (matrices -> image) lives in overlay_math and is tested
without a window; only the few gpu calls here need one.
"""
from __future__ import annotations

import bpy
import numpy as np

from . import splat_cache
from .overlay_math import SplatOverlay, to_display
from .splat_object import PROXY_MODIFIER, is_splat_object

FAR_NDC = 0.999999  # depth of the quad: behind every mesh, in front of the cleared background (1.0)

_handle = None
_overlays: dict[int, SplatOverlay] = {}  # splat_cache.uid(object) -> its images over the shared renderer
_textures: dict[tuple[str, int], tuple[int, float, object]] = {}  # (object, region) -> (image id, exposure, tex)
last_error: str | None = None


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


def _texture(obj_name: str, slot: int, img, exposure: float):
    import gpu
    key = (obj_name, slot)
    cached = _textures.get(key)
    if cached is not None and cached[0] == id(img) and cached[1] == exposure:
        return cached[2]
    px = np.ascontiguousarray(to_display(img.rgba, exposure)[::-1], np.float32)  # GPU rows go bottom-up
    h, w = px.shape[:2]
    buf = gpu.types.Buffer("FLOAT", h * w * 4, px.ravel())
    tex = gpu.types.GPUTexture((w, h), format="RGBA32F", data=buf)
    _textures[key] = (id(img), exposure, tex)
    return tex


def _draw_quad(tex, rect) -> None:
    import gpu
    from gpu_extras.batch import batch_for_shader
    from mathutils import Matrix
    x0, y0, x1, y1 = rect
    shader = gpu.shader.from_builtin("IMAGE")
    batch = batch_for_shader(shader, "TRI_FAN", {"pos": ((x0, y0), (x1, y0), (x1, y1), (x0, y1)),
                                                 "texCoord": ((0, 0), (1, 0), (1, 1), (0, 1))})
    far = Matrix(((1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 0, FAR_NDC), (0, 0, 0, 1)))  # every vertex at z = FAR_NDC
    depth_test, depth_mask, blend = gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get()
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(False)
    gpu.state.blend_set("ALPHA_PREMULT")
    try:
        with gpu.matrix.push_pop():
            gpu.matrix.load_identity()
            with gpu.matrix.push_pop_projection():
                gpu.matrix.load_projection_matrix(far)
                shader.bind()
                shader.uniform_sampler("image", tex)
                batch.draw(shader)
    finally:
        gpu.state.depth_test_set(depth_test)
        gpu.state.depth_mask_set(depth_mask)
        gpu.state.blend_set(blend)


def draw_callback() -> None:
    global last_error
    context = bpy.context
    settings = getattr(context.scene, "gs_ibl_overlay", None)
    rv3d, region = context.region_data, context.region
    if settings is None or not settings.show or rv3d is None or region is None:
        return
    try:
        eye = np.linalg.inv(np.array(rv3d.view_matrix))[:3, 3]
        objs = [o for o in context.visible_objects if is_splat_object(o)]
        objs.sort(key=lambda o: -np.linalg.norm(np.array(o.matrix_world.translation) - eye))  # far first
        slot = region.as_pointer()
        for obj in objs:
            img = splat_image(obj, rv3d, region.width, region.height, settings.resolution_scale, slot)
            _draw_quad(_texture(obj.name, slot, img, settings.exposure), img.view.ndc_rect)
        last_error = None
    except Exception as e:  # noqa: BLE001  a draw handler that raises would print on every redraw
        if str(e) != last_error:
            print(f"GS-IBL overlay: {e}")
        last_error = str(e)


def _tag_redraw() -> None:
    wm = bpy.context.window_manager
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def settings_changed(settings, context) -> None:
    """Overlay toggled or its resolution changed: hide the point proxies while the overlay shows, redraw."""
    for obj in bpy.data.objects:
        if is_splat_object(obj):
            mod = obj.modifiers.get(PROXY_MODIFIER)
            if mod is not None:
                mod.show_viewport = not settings.show
    if not settings.show:
        clear_cache()
    _tag_redraw()


def register_overlay() -> None:
    global _handle
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")


def unregister_overlay() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    clear_cache()
