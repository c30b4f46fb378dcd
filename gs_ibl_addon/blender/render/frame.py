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

Shadows on Splats (the scene's render settings): the meshes darken the splat surface under them, lit from the probe
whose World the scene uses (its environment and the suns its bake split off), by core/render/shadows.py, in numpy
on FRONT and BEHIND before they are written: so Cycles and EEVEE, and every Blender, get the same shadows. A scene
whose World is not a baked probe's gets none, and the render says so once.
"""
from __future__ import annotations

import threading
import time

import numpy as np
from bpy.app.handlers import persistent

from ...core import limits
from ...core.render import shadows
from ...core.render.mesh_depth import mesh_depth
from ..common import handlers
from ..common.datablocks import MARKER, image_pixels, is_probe
from ..common.jobs import gpu
from ..splats.object import is_splat_object
from . import compositor, setup, splats
from .camera import NotDrawn, frame_camera, not_followed

PREFIX = "GS-IBL render: "
_job: dict | None = None  # the render job running now (between render_init and render_complete/cancel)
_last: dict[str, dict] = {}  # scene name -> the last render's messages and per-frame record (panel, tests)
PROBE_OWNER_KEY = "gs_ibl_probe"  # lighting/lights_from_probe.OWNER_KEY: on a light, the probe that made it
RADIANCE_NODE, STRENGTH_NODE = "GS-IBL Radiance", "GS-IBL Strength"  # lighting/world.py build_world's nodes


def rendering() -> bool:
    return _job is not None


def last_render(scene) -> dict:
    """{"messages": [...], "frames": {frame: {...}}, "cancelled": bool} of the scene's last render. A frame's record
    holds each view layer's under "layers" ({name: {"objects", "splats", "ms", ...}}) and over them the frame's
    totals (_file)."""
    return _last.get(scene.name, {"messages": [], "frames": {}, "cancelled": False})


NO_PROBE_WORLD = "no shadows on the splats: the scene's World is not a baked probe's"  # probe_light's message


def _is_probe_world(world) -> bool:
    return world is not None and world.get(MARKER) == "world" and world.node_tree is not None


def messages_now(scene) -> list[str]:
    """The last render's messages that still hold: that the World was no baked probe's goes once a bake made it
    one (the panel showed it under the bake's report, as if the bake had not helped)."""
    return [m for m in last_render(scene)["messages"]
            if not (m.startswith(NO_PROBE_WORLD) and _is_probe_world(scene.world))]


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
    if compositor.shows_world(scene) and compositor.world_pass_empty(scene):
        say("the World is not shown behind the splats: Blender 4.2's EEVEE leaves it out of the Environment pass "
            "under Film Transparent (Cycles shows it); the background is transparent")


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


def _albedo(ob) -> np.ndarray:
    """The diffuse RGB a mesh reflects light with, as far as its active material says it plainly: a Principled or
    Diffuse BSDF's colour where nothing is linked into it, else the material's viewport colour; without a
    material Blender's default grey, 0.8."""
    mat = getattr(ob, "active_material", None)
    if mat is None:
        return np.full(3, 0.8)
    nt = getattr(mat, "node_tree", None)
    for node in (nt.nodes if nt is not None else ()):
        if node.bl_idname in ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse"):
            sock = node.inputs.get("Base Color") or node.inputs.get("Color")
            if sock is not None and not sock.is_linked:
                return np.array(sock.default_value[:3], np.float64)
            break
    return np.array(mat.diffuse_color[:3], np.float64)


def _mesh_triangles(dg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space triangles (m, 3, 3) of the meshes the camera sees and of those that cast shadows (Object >
    Visibility > Ray Visibility: Camera, Shadow; evaluated: modifiers, instances), and the casters' diffuse colour
    (RGB, their mean by area).

    Everything the engines render as a mesh is a MESH instance of the evaluated depsgraph: a text, a curve with a
    bevel or extrusion, a surface, a metaball (their evaluated mesh comes as an instance of the object), collection
    and geometry-nodes instances. Not meshes, and not here: curves (hair), point clouds, volumes, lights, cameras.
    An instance is seen as its instancer lets it be, as Cycles does (both visibilities ANDed)."""
    out, seen_by, casts, albedo = [], [], [], []
    for inst in dg.object_instances:
        ob = inst.object
        if ob.type != "MESH" or is_splat_object(ob.original):
            continue
        seen, shadow = getattr(ob, "visible_camera", True), getattr(ob, "visible_shadow", True)
        parent = inst.parent if inst.is_instance else None
        if parent is not None:
            seen = seen and getattr(parent, "visible_camera", True)
            shadow = shadow and getattr(parent, "visible_shadow", True)
        if not (seen or shadow) or (parent is not None and is_splat_object(parent.original)):
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
        seen_by.append(np.full(len(tris), bool(seen)))
        casts.append(np.full(len(tris), bool(shadow)))
        albedo.append(np.broadcast_to(_albedo(ob), (len(tris), 3)))
    if not out:
        return np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), np.zeros(3)
    tri = np.concatenate(out)
    cast = np.concatenate(casts)
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)[cast]
    mean = (np.concatenate(albedo)[cast] * area[:, None]).sum(0) / max(area.sum(), 1e-30) if cast.any() else np.zeros(3)
    return tri[np.concatenate(seen_by)], tri[cast], mean


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
    _file(_job["record"]["frames"].setdefault(frame, {"layers": {}}), layer, record)


def _file(frame_record: dict, layer: str, record: dict) -> None:
    """``record`` as view layer ``layer``'s of its frame (frame_change_post runs once per view layer, each with its
    own images); the frame's own fields sum its layers' (times, splats, triangles), join their object lists and
    messages, so a one-layer frame reads as its layer's record."""
    frame_record["layers"][layer] = record
    layers = list(frame_record["layers"].values())
    for key in {k for r in layers for k in r}:
        values = [r[key] for r in layers if key in r]
        if key == "light_samples":
            frame_record[key] = max(values)
        elif key == "objects":
            frame_record[key] = sorted({n for v in values for n in v})
        elif isinstance(values[0], list):
            frame_record[key] = [x for v in values for x in v]
        elif isinstance(values[0], (int, float)):
            frame_record[key] = round(sum(values), 1) if isinstance(values[0], float) else sum(values)


def _draw(dg, cam, items, record) -> tuple[np.ndarray, np.ndarray]:
    """FRONT and BEHIND of the frame, the size of the compositor's images, rows top first."""
    t0 = time.perf_counter()
    tris, casters, albedo = _mesh_triangles(dg)
    rs = getattr(dg.scene_eval, "gs_ibl_render", None)
    shadowed = bool(getattr(rs, "shadows", False)) and len(casters) > 0
    z = mesh_depth(tris, cam.matrix, cam.tan_x, cam.tan_y, cam.width, cam.height, cam.cx, cam.cy, cam.window,
                   near=cam.clip_start, far=cam.clip_end)
    t1 = time.perf_counter()
    no_mesh = ~np.isfinite(z)
    cut = np.where(no_mesh, np.float32(cam.clip_end), z)  # no mesh: the far clip (splats beyond it not drawn)
    with gpu:  # the shared Vulkan queue (a bake's worker may be using it)
        renderer = splats.renderer_for(items, cam.clip_start)
        check_fits(cam, renderer.scene_count, renderer.ctx)
        try:
            depth = [] if shadowed else None
            front, behind = splats.render_layers(renderer, cam, cut, depth)
        except limits.TooBig as e:
            raise NotDrawn(f"splats not drawn: {e} (Output Properties > Resolution, or its %, or a render "
                           "border)") from None
    t2 = time.perf_counter()
    if shadowed and depth and depth[0] is not None:
        front, behind = _shadow(dg, cam, front, behind, depth[0], (casters, albedo), no_mesh,
                                float(rs.shadow_strength), record)
    # one full-frame array: astype copied the float32 result of np.where a second time
    behind = np.where(no_mesh[..., None], np.float32(0.0), behind.astype(np.float32, copy=False))
    record.update(splats=int(renderer.scene_count), triangles=int(len(tris)),
                  ms_mesh_depth=round(1e3 * (t1 - t0), 1), ms_splats=round(1e3 * (t2 - t1), 1))
    if cam.window is not None and not cam.crop:  # a full-size frame, splats only where Blender renders
        x0, y0, x1, y1 = cam.window
        full = np.zeros((cam.height, cam.width, 4), np.float32), np.zeros((cam.height, cam.width, 4), np.float32)
        full[0][y0:y1, x0:x1], full[1][y0:y1, x0:x1] = front, behind
        front, behind = full
    return front, behind


def probe_light(scene, scale: float = 1.0) -> tuple[shadows.LightSamples | None, str | None]:
    """(the light samples of the probe whose World ``scene`` uses: the World's radiance image at its strength and
    the suns the probe's bake split off, ``scale`` times the usual counts, or None; why not, or None)."""
    world = scene.world
    if not _is_probe_world(world):
        return None, NO_PROBE_WORLD + " (bake a probe, or turn Shadows on Splats off in the GS-IBL panel)"
    env = world.node_tree.nodes.get(RADIANCE_NODE)
    image = getattr(env, "image", None)
    if image is None or not image.size[0] or not image.size[1]:
        return None, f"no shadows on the splats: World '{world.name}' has no radiance image (bake its probe again)"
    latlong = image_pixels(image)[::-1, :, :3]  # rows top first (+Z), as lighting/world.py wrote them
    node = world.node_tree.nodes.get(STRENGTH_NODE)
    strength = float(node.inputs["Strength"].default_value) if node is not None else 1.0
    probes = {o.name for o in scene.objects if is_probe(o) and getattr(o.gs_ibl_probe, "world", None) == world}
    lights = []
    for o in scene.objects:
        if o.type == "LIGHT" and o.get(PROBE_OWNER_KEY) in probes and o.data.type == "SUN" and not o.hide_render:
            m = np.array(o.matrix_world, np.float64)
            irr = float(o.data.energy) * np.asarray(o.data.color, np.float64)
            lights.append({"direction": m[:3, 2] / np.linalg.norm(m[:3, 2]), "irradiance": irr,  # +Z: toward it
                           "angle": float(np.degrees(o.data.angle))})
    return shadows.light_samples(latlong, strength, lights, scale), None


def _shadow(dg, cam, front, behind, depth, casters, no_mesh, strength, record) -> tuple[np.ndarray, np.ndarray]:
    """FRONT and BEHIND with the shadows of ``casters`` (triangles, their diffuse colour) on the splat surface
    (core/render/shadows.py)."""
    t0 = time.perf_counter()
    tris, albedo = casters
    scale = shadows.sample_scale(len(tris))
    lights = _job.setdefault("light", {})
    if scale not in lights:  # once per render job (and caster budget): the World's image read, the light sampled
        lights[scale] = probe_light(dg.scene, scale)
    samples, why = lights[scale]
    if samples is None:
        say(why)
        return front, behind
    if scale < 1:
        say(f"shadows on the splats from fewer light directions ({samples.count}) to keep the frame's time: the "
            f"meshes have {len(tris):,} triangles (softer steps in the penumbrae)")
    alpha = 1.0 - (1.0 - front[..., 3]) * (1.0 - behind[..., 3])
    ratio = shadows.frame_ratio(depth, alpha, tris, samples, cam.matrix, cam.tan_x, cam.tan_y, cam.width,
                                cam.height, cam.cx, cam.cy, cam.window, albedo=albedo)
    front, behind = shadows.apply(front, behind, ratio, no_mesh, strength)
    record.update(ms_shadows=round(1e3 * (time.perf_counter() - t0), 1), light_samples=samples.count)
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
        if depsgraph.id_type_updated("SCENE") and setup.enabled(scene) and compositor.installed(scene):
            compositor.sync_world(scene)  # the engine changed: the World under the splats where its pass holds it


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
