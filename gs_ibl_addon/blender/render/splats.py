"""The splats of a frame: which objects the render sees, one GPU scene of them all, and the layered render.

All render-visible splat objects are drawn as one scene (their world-space SplatScenes concatenated), so they are
sorted together and cross each other splat by splat. The upload is kept between frames and renders, keyed by every
object's data key (splats/cache.py: geometry, point count, edits) and its world matrix at the frame: a camera move
uploads nothing, a moving splat object uploads the scene again (its splats are read from Blender once per render
job and kept until the job ends).

Which objects: our mesh splat objects the render depsgraph holds (their camera icon, hide_render, on; Object >
Visibility > Camera on). Blender 5.3's native splat Point Clouds are the user's choice (Scene.gs_ibl_render.
native_splats): left to Blender, which renders them itself, or drawn by us with the rest (read as a bake reads them:
splats/object.py read_steps). Then Blender must not draw them too: their copy in the render's depsgraph (evaluated,
its camera visibility) is turned off for this render alone, once we drew their frame, after that depsgraph was
evaluated for the frame and before the engine reads it (frame_change_post); the user's object is never written,
so nothing needs restoring after the render, on Esc or on an undo, and a frame we cannot draw leaves them to
Blender.
"""
from __future__ import annotations

import inspect
from collections import OrderedDict

import numpy as np

from ...core.scene import SplatScene, combine_scenes
from ..common.datablocks import MARKER
from ..common.jobs import run_now
from ..splats.cache import data_key
from ..splats.object import (PROXY_TREE_ROLE, colour_space_of, current_layer, in_view_layer, is_mesh_splats,
                             is_native_splats, read_steps, to_world)

KEEP = 2  # GPU scenes kept (two view layers with different objects alternate without uploads)
_renderers: "OrderedDict[tuple, object]" = OrderedDict()
_locals: dict[tuple, SplatScene] = {}  # geometry key -> the object's splats in object space, during a render job
_hidden: set[str] = set()  # native objects we draw in this render job (their evaluated copies hidden from Blender)
_taken: list = []  # evaluated copies of the native objects the frame being drawn holds (hide_taken)
uploads = 0  # scenes uploaded so far (tests see when a frame re-used the GPU copy)


def draws_native(scene) -> bool:
    """Whether F12 draws Blender 5.3's native splat objects with our renderer (Native Splats: GS-IBL)."""
    s = getattr(scene, "gs_ibl_render", None)
    return getattr(s, "native_splats", "BLENDER") == "GSIBL"


def collect(dg) -> tuple[list[tuple[object, np.ndarray]], list[str]]:
    """(splat objects we draw, each (original object, world matrix at this frame): instances included; names of
    native splat objects left to Blender). With Native Splats: GS-IBL the native ones the camera sees are ours, and
    their evaluated copies are hidden from the render's engine once drawn (hide_taken; module docstring)."""
    ours, native = [], []
    _taken.clear()
    with_native = draws_native(dg.scene)
    for inst in dg.object_instances:
        ob = inst.object
        orig = ob.original
        if is_mesh_splats(orig):
            if getattr(ob, "visible_camera", True):
                ours.append((orig, np.array(inst.matrix_world, np.float64)))
        elif is_native_splats(orig):
            if not with_native:
                native.append(orig.name)
                continue
            # one evaluated copy serves every instance of it, and a persistent render keeps it between frames:
            # what we hid is known by name for the rest of the job
            if getattr(ob, "visible_camera", True) or orig.name in _hidden:
                ours.append((orig, np.array(inst.matrix_world, np.float64)))
                _taken.append(ob)
    return ours, native


def hide_taken() -> None:
    """The native objects of the last collect() hidden from Blender's engine in this render (their evaluated copies'
    camera visibility): render_layers calls it once their frame is drawn, so a frame we cannot draw (too large for
    the device, an error) leaves them to Blender."""
    for ob in _taken:
        ob.visible_camera = False
        _hidden.add(ob.original.name)
    _taken.clear()


def render_visible(scene, view_layer=None) -> tuple[list, list, list]:
    """(splat objects that F12 draws with our renderer, ours with the camera icon off, native ones Blender renders)
    among the scene's objects, as the panel says it (no depsgraph: the objects as they are now). Native ones are in
    the first list with Native Splats: GS-IBL."""
    layer = view_layer or current_layer(scene)
    with_native = draws_native(scene)
    drawn, hidden, native = [], [], []
    for ob in scene.objects:
        if is_mesh_splats(ob) or (with_native and is_native_splats(ob)):
            visible = not ob.hide_render and ob.visible_camera and in_view_layer(ob, layer)
            (drawn if visible else hidden).append(ob)
        elif is_native_splats(ob) and not ob.hide_render:
            native.append(ob)
    return drawn, hidden, native


def proxy_modifiers(ob) -> list:
    """The point-proxy modifiers of our splat object (viewport display only: never rendered)."""
    return [m for m in ob.modifiers if m.type == "NODES" and m.node_group is not None
            and m.node_group.get(MARKER) == PROXY_TREE_ROLE]


def _key(ob, matrix: np.ndarray) -> tuple:
    return (*data_key(ob)[:3], matrix.tobytes(), colour_space_of(ob))


def _world_scene(ob, matrix: np.ndarray) -> SplatScene:
    geometry = data_key(ob)[:3]
    local = _locals.get(geometry)
    if local is None:
        local, _ = run_now(read_steps(ob))
        _locals[geometry] = local
    local.colour_space = colour_space_of(ob)
    return to_world(local, matrix, ob.name)


def renderer_for(items: list[tuple[object, np.ndarray]], near: float):
    """The GPU scene of ``items`` ((object, world matrix)), uploaded when any of them changed (the caller holds
    the GPU lock: common/jobs.py gpu)."""
    global uploads
    key = (tuple(sorted(_key(ob, m) for ob, m in items)), float(near))
    r = _renderers.get(key)
    if r is not None:
        _renderers.move_to_end(key)
        return r
    from ...core.render.renderer import SplatRenderer  # Vulkan loads when splats are first drawn
    scene = combine_scenes([_world_scene(ob, m) for ob, m in sorted(items, key=lambda it: it[0].name)])
    while len(_renderers) >= KEEP:
        _renderers.popitem(last=False)[1].close()
    r = SplatRenderer(scene, near=near)
    r.colour_space = scene.colour_space
    _renderers[key] = r
    uploads += 1
    return r


def end_job() -> None:
    """A render job ended: the objects' splats read for it are let go (the GPU scenes stay for the next F12)."""
    _locals.clear()
    _hidden.clear()
    _taken.clear()


def clear() -> None:
    end_job()
    while _renderers:
        _renderers.popitem()[1].close()


# ---- the layered render ----

def has_depth_cut() -> bool:
    """Whether the core renders a camera with a per-pixel depth cut (ViewBatch.camera, render(cut=...))."""
    from ...core.render.renderer import SplatRenderer
    from ...core.render.views import ViewBatch
    return hasattr(ViewBatch, "camera") and "cut" in inspect.signature(SplatRenderer.render).parameters


def render_layers(renderer, cam, cut: np.ndarray, depth: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """FRONT and BEHIND (H, W, 4) premultiplied RGBA, rows top first, of the camera's window (its whole frame
    without a border): the splats nearer than ``cut`` (planar depth per pixel of the window) and the rest.

    Without the core's depth cut (has_depth_cut), the plain frame is FRONT and BEHIND is zero: splats always in
    front of meshes. ``depth``: a list that gets the splats' (H, W) depth of FRONT over BEHIND appended (the
    shadows' receivers, core/render/shadows.py), or None where the core gives none. Once drawn, the native objects
    among them are hidden from Blender's engine (hide_taken)."""
    layers = _layers(renderer, cam, cut, depth)
    hide_taken()
    return layers


def _layers(renderer, cam, cut: np.ndarray, depth: list | None) -> tuple[np.ndarray, np.ndarray]:
    from ...core.render.views import ViewBatch
    window = cam.window
    if has_depth_cut():
        batch = ViewBatch.camera(cam.matrix, cam.tan_x, cam.tan_y, cam.width, cam.height, shift=(cam.cx, cam.cy),
                                 window=window)
        cut = np.asarray(cut, np.float32)
        if hasattr(renderer, "render_camera"):  # arrays in, arrays out; refuses a frame the device cannot hold
            f = renderer.render_camera(batch, cut=cut, depth=depth is not None, timestamps=False)
            if depth is not None:
                depth.append(f.depth)
            return f.front, f.behind
        res = renderer.render(batch, cut=cut)
        return res.images[0], res.behinds[0]
    front = _plain(renderer, cam)
    return front, np.zeros_like(front)


def _plain(renderer, cam) -> np.ndarray:
    """The fallback's FRONT: a centred pinhole frame that covers the shifted one at the same pixel size, cropped
    to it (the shift rounded to whole pixels), then to the window."""
    from ...core.render.mesh_depth import camera_basis
    from ...core.render.views import View, ViewBatch
    b = camera_basis(cam.matrix)
    px, py = 2.0 * cam.tan_x / cam.width, 2.0 * cam.tan_y / cam.height
    ox, oy = int(round(cam.cx / px)), int(round(-cam.cy / py))  # the shift in pixels, right and down
    w2, h2 = cam.width + 2 * abs(ox), cam.height + 2 * abs(oy)
    view = View(-b[:3, 2], b[:3, 0], -b[:3, 1], cam.tan_x * w2 / cam.width, cam.tan_y * h2 / cam.height, w2, h2)
    img = renderer.render(ViewBatch(b[:3, 3].copy(), (view,), px)).images[0]
    x0, y0 = abs(ox) + ox, abs(oy) + oy
    img = img[y0:y0 + cam.height, x0:x0 + cam.width]
    if cam.window is not None:
        wx0, wy0, wx1, wy1 = cam.window
        img = img[wy0:wy1, wx0:wx1]
    return np.ascontiguousarray(img)
