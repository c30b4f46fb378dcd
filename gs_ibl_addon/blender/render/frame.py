"""The render handlers: the splats drawn for every frame of a final render (F12, Render Animation, ``-f``/``-a``).

Blender calls, per render job (docs/final-frame.md, section 2, identical in 4.2-5.3): render_init once, then for
each frame (and each view layer) frame_change_post with the render pipeline's depsgraph (mode RENDER, evaluated at
that frame: the camera and objects as they are there), then the engine and the compositor, and after the last
frame render_complete, or render_cancel on Esc. In Blender's window these run on the render job's thread.

For each frame and view layer (``fill``): the scene camera at the output resolution (camera.py), the render-visible
meshes' depth (core/render/mesh_depth.py, with the edge fill), the splats of all render-visible splat objects as one
scene split at that depth into FRONT and BEHIND (splats.py), written into the view layer's two images, which the
compositor puts in front of and behind the render (compositor.py). A frame's images are written only once both
layers are complete. Where the splats cannot be drawn (no camera, an orthographic or panoramic one, a frame too
large for the device, an error) both images are cleared, so no splats of another frame appear, and the reason is
said once per render, in the console and in the panel.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from bpy.app.handlers import persistent

from ...core import limits
from ...core.render.mesh_depth import mesh_depth
from ..common import handlers
from ..common.jobs import gpu
from ..splats.object import is_splat_object
from . import compositor, setup, splats
from .camera import NotDrawn, frame_camera, not_followed

PREFIX = "GS-IBL render: "
_job: dict | None = None  # the render job running now (between render_init and render_complete/cancel)
_last: dict[str, dict] = {}  # scene name -> the last render's messages and per-frame record (panel, tests)


def rendering() -> bool:
    return _job is not None


def last_render(scene) -> dict:
    """{"messages": [...], "frames": {frame: {...}}, "cancelled": bool} of the scene's last render."""
    return _last.get(scene.name, {"messages": [], "frames": {}, "cancelled": False})


def say(text: str) -> None:
    """A message of this render, once per render: the console and the panel."""
    if _job is None or text in _job["said"]:
        return
    _job["said"].add(text)
    _job["record"]["messages"].append(text)
    print(PREFIX + text, flush=True)


def _on_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@persistent
def on_render_init(scene, *_args) -> None:
    global _job
    if not setup.enabled(scene):
        _job = None
        return
    record = {"messages": [], "frames": {}, "cancelled": False}
    _last[scene.name] = record
    _job = {"scene": scene.name, "said": set(), "record": record, "objects": {}, "warned_settings": False}
    if _on_main_thread():  # -b, scripts: the nodes can still be put in place now
        try:
            setup.ensure(scene)
        except Exception as e:  # noqa: BLE001 (a render must not fail on our account)
            say(f"the compositor could not be set up ({type(e).__name__}: {e}); splats not drawn")
    if scene.camera is None:
        say("splats not drawn: the scene has no camera (Scene Properties > Camera)")


@persistent
def on_render_end(scene, *_args) -> None:
    global _job
    if _job is not None:
        splats.end_job()
        _job = None


@persistent
def on_render_cancel(scene, *_args) -> None:
    if _job is not None:
        _job["record"]["cancelled"] = True
        done = sorted(_job["record"]["frames"])
        say("render cancelled: the frames finished before it were written whole" + (f" ({done})" if done else ""))
    on_render_end(scene)


@persistent
def on_frame_change_post(scene, depsgraph=None) -> None:
    if _job is None or depsgraph is None or depsgraph.mode != "RENDER" or not setup.enabled(scene):
        return
    try:
        fill(scene, depsgraph)
    except Exception as e:  # noqa: BLE001 (Blender prints a handler's traceback and goes on; ours says what it is)
        say(f"splats not drawn: {type(e).__name__}: {e}")


def _mesh_triangles(dg) -> np.ndarray:
    """World-space triangles (m, 3, 3) of the meshes the camera sees (evaluated: modifiers, instances)."""
    out = []
    for inst in dg.object_instances:
        ob = inst.object
        if ob.type != "MESH" or not ob.visible_camera or is_splat_object(ob.original):
            continue
        me = ob.data
        if hasattr(me, "calc_loop_triangles"):
            me.calc_loop_triangles()
        tris = me.loop_triangles
        if not len(tris) or not len(me.vertices):
            continue
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        idx = np.empty(len(tris) * 3, np.int32)
        tris.foreach_get("vertices", idx)
        m = np.array(inst.matrix_world, np.float64)
        v = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        out.append(v[idx.reshape(-1, 3)])
    return np.concatenate(out) if out else np.zeros((0, 3, 3))


def check_fits(cam, splat_count: int, ctx) -> None:
    """Refuse a frame the device or the host cannot hold, naming the size that fits (core/limits.py)."""
    w, h = cam.image_size if cam.window is None else (cam.window[2] - cam.window[0], cam.window[3] - cam.window[1])

    def need(side: int) -> tuple[int, int]:
        s = side / max(w, h)
        pw, ph = max(int(w * s), 1), max(int(h * s), 1)
        gpu_bytes, host = limits.image_bytes(pw, ph, splat_count)
        return gpu_bytes + pw * ph * 36, host + pw * ph * 72  # BEHIND, the cut; their read-backs, the mesh depth

    try:
        limits.check_fits("resolution", max(w, h), need(max(w, h)), need, ctx, what=" px (the frame's larger side)")
    except limits.TooBig as e:
        raise NotDrawn(f"splats not drawn: a {w}x{h} frame is too large: {e} (Output Properties > Resolution, "
                       "or its %, or a render border)") from None


def fill(scene, dg) -> None:
    t0 = time.perf_counter()
    layer = dg.view_layer.name
    front_im = compositor.find_image(scene, layer, compositor.FRONT_ROLE)
    behind_im = compositor.find_image(scene, layer, compositor.BEHIND_ROLE)
    if front_im is None or behind_im is None:
        say(f"splats not drawn in view layer '{layer}': the compositor nodes are missing (turn Splats in Renders "
            "off and on again in the GS-IBL panel)")
        return
    record = {"splats": 0, "objects": [], "messages": []}
    frame = dg.scene_eval.frame_current
    size = compositor.output_size(dg.scene_eval)
    front = behind = None
    try:
        cam = frame_camera(dg)
        size = cam.image_size
        if not _job["warned_settings"]:
            _job["warned_settings"] = True
            for text in not_followed(dg):
                say(text)
        items, native = splats.collect(dg)
        names = sorted({ob.name for ob, _ in items})
        before = _job["objects"].get(layer)  # per view layer: each may show other objects
        if before is not None and names != before:
            gone = [n for n in before if n not in names]
            if gone:
                say(f"from frame {frame} on, no splats of {', '.join(gone)} (deleted, hidden or camera icon off)")
        _job["objects"][layer] = names
        record["objects"] = names
        if items:
            front, behind = _draw(dg, cam, items, record)
    except NotDrawn as e:
        say(str(e))
    if front is None:
        front = behind = np.zeros((size[1], size[0], 4), np.float32)
    _write(front_im, front)
    _write(behind_im, behind)
    record["ms"] = round(1e3 * (time.perf_counter() - t0), 1)
    _job["record"]["frames"][frame] = record


def _draw(dg, cam, items, record) -> tuple[np.ndarray, np.ndarray]:
    """FRONT and BEHIND of the frame, the size of the compositor's images, rows top first."""
    t0 = time.perf_counter()
    tris = _mesh_triangles(dg)
    z = mesh_depth(tris, cam.matrix, cam.tan_x, cam.tan_y, cam.width, cam.height, cam.cx, cam.cy, cam.window,
                   near=cam.clip_start, far=cam.clip_end)
    t1 = time.perf_counter()
    no_mesh = ~np.isfinite(z)
    cut = np.where(no_mesh, np.float32(cam.clip_end), z)  # no mesh: the far clip (splats beyond it not drawn)
    with gpu:  # the shared Vulkan queue (a bake's worker may be using it)
        renderer = splats.renderer_for(items, cam.clip_start)
        check_fits(cam, renderer.scene_count, renderer.ctx)
        try:
            front, behind = splats.render_layers(renderer, cam, cut)
        except limits.TooBig as e:
            raise NotDrawn(f"splats not drawn: {e} (Output Properties > Resolution, or its %, or a render "
                           "border)") from None
    behind = np.where(no_mesh[..., None], 0.0, behind).astype(np.float32)
    record.update(splats=int(renderer.scene_count), triangles=int(len(tris)),
                  ms_mesh_depth=round(1e3 * (t1 - t0), 1), ms_splats=round(1e3 * (time.perf_counter() - t1), 1))
    if cam.window is not None and not cam.crop:  # a full-size frame, splats only where Blender renders
        x0, y0, x1, y1 = cam.window
        full = np.zeros((cam.height, cam.width, 4), np.float32), np.zeros((cam.height, cam.width, 4), np.float32)
        full[0][y0:y1, x0:x1], full[1][y0:y1, x0:x1] = front, behind
        front, behind = full
    return front, behind


def _write(im, rgba: np.ndarray) -> None:
    """``rgba`` (rows top first) into the image (rows bottom first), resized to it where needed."""
    h, w = rgba.shape[:2]
    if tuple(im.size) != (w, h):
        im.scale(w, h)
    im.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], np.float32).ravel())
    im.update()


@persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    if _job is None:  # never during a render (its handlers may run on another thread)
        setup.on_depsgraph_update(scene, depsgraph)


@persistent
def on_load_post(*_args) -> None:
    setup.on_load_post()


@persistent
def on_load_pre(*_args) -> None:
    splats.clear()
    _last.clear()


_HANDLERS = (("render_init", on_render_init), ("render_complete", on_render_end),
             ("render_cancel", on_render_cancel), ("frame_change_post", on_frame_change_post),
             ("depsgraph_update_post", on_depsgraph_update), ("load_post", on_load_post), ("load_pre", on_load_pre))


def register_handlers() -> None:
    handlers.add(_HANDLERS)


def unregister_handlers() -> None:
    global _job
    handlers.remove(_HANDLERS)
    _job = None
    with gpu:
        splats.clear()
