"""Final-frame probe (issue 36 groundwork): handler-filled float images composited with the render, per frame.

Runs inside a real Blender (bpy module or binary) for the jobs that need Blender, and in any Python with numpy and
OpenImageIO for the check:

  build   make the scene (three meshes, an animated camera, the compositor wired for this version) and save it
  render  register the handlers; with --how f1|anim|still render in-process (bpy.ops.render.render: animation of
          frames 1..1 = the `-f 1` code path, 1..3 = `-a`, write_still at frame 2 = F12); with --how none the
          handlers are only registered (the binary's own `-f 1` / `-a` that follow on its command line render)
  check   read the written EXRs and compare every frame with a numpy reference (no bpy)

The "splats" are synthetic: SHEETS camera-facing semi-transparent planes (a wall across y in [-0.5, 0.5]) whose colour
depends on the frame number, the camera position and world x. The handler (frame_change_post with the render
pipeline's depsgraph) rasterises the render-visible meshes' depth from the scene camera in numpy and splits the
sheets' front-to-back blend at that depth into FRONT and BEHIND premultiplied images; the compositor does
FRONT over (Render over BEHIND). A Z Combine of the full blend at one splat depth is wired beside it for comparison.
tests/real_blender/final_frame_probe.sh runs it in each Blender of scripts/blender_roots.sh; docs/final-frame.md
has what it found.
"""
from __future__ import annotations

import json
import math
import os
import sys
import threading
import time

import numpy as np

# ---- the scene, shared by Blender's side and the checker (which rebuilds it without bpy) ----
RES = (128, 96)  # at PERCENT %: the output is 64x48
PERCENT = 50
LENS, SENSOR, SHIFT_X = 50.0, 36.0, 0.04  # sensor_fit HORIZONTAL
CAM_X = {1: -0.4, 2: 0.0, 3: 0.4}  # keyframed camera x per frame; at y=-6 looking along +y
CAM_Y = -6.0
SHEET_Y = np.linspace(-0.5, 0.5, 6)  # the wall: six sheets, each alpha 0.25
SHEET_A = 0.25
SHEET_BASE = np.array([[0.9, 0.3, 0.2], [0.8, 0.6, 0.1], [0.3, 0.8, 0.3], [0.2, 0.6, 0.8], [0.5, 0.3, 0.9],
                       [0.9, 0.4, 0.7]])
MESHES = {  # name: (kind, centre, size, z-rotation deg, emission colour)
    "Tilted": ("plane", (0.0, 0.0, 0.0), (2.4, 0.9), 50.0, (0.1, 0.15, 0.9)),  # crosses the wall (y -0.92..0.92)
    "Front": ("cube", (-0.95, -1.2, 0.55), (0.5, 0.5), 0.0, (0.9, 0.9, 0.1)),  # in front of every sheet
    "Back": ("cube", (0.95, 1.2, -0.55), (0.5, 0.5), 0.0, (0.1, 0.9, 0.8)),  # behind every sheet
}
FAR = 1.0e10
CROP = (0.25, 0.75, 0.5, 1.0)  # border min x, max x, min y, max y of the crop run
TAG = "FINAL-FRAME-PROBE "


def mesh_geometry(kind, centre, size, rot_deg):
    """World-space vertices (n, 3) and triangles (m, 3) of one probe mesh."""
    if kind == "plane":
        w, h = size
        v = np.array([[-w / 2, 0, -h / 2], [w / 2, 0, -h / 2], [w / 2, 0, h / 2], [-w / 2, 0, h / 2]])
        t = np.array([[0, 1, 2], [0, 2, 3]])
    else:
        s = size[0] / 2
        v = np.array([[x, y, z] for x in (-s, s) for y in (-s, s) for z in (-s, s)], float)
        t = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    a = math.radians(rot_deg)
    rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    return v @ rz.T + np.array(centre), t


def sheet_colour(k, frame, cam_x, wx):
    """Premultiplied-free colour of sheet k at world x positions wx: frame-dependent, with a gradient in
    (world x - camera x), so both the frame and the camera show in every pixel."""
    base = SHEET_BASE[k] * (0.4 + 0.2 * frame)
    grad = 0.25 + 0.25 * np.sin(3.0 * (wx - cam_x))
    c = np.empty(wx.shape + (3,))
    c[..., 0] = base[0]
    c[..., 1] = base[1] * (0.5 + grad)
    c[..., 2] = base[2] + 0.1 * cam_x
    return np.clip(c, 0.0, None)


def pixel_rays(inv_viewproj, w, h, ss=1):
    """World-space ray origins and unit directions through the centres of (ss x ss) sub-pixels, rows bottom-up."""
    xs = (np.arange(w * ss) + 0.5) / (w * ss) * 2 - 1
    ys = (np.arange(h * ss) + 0.5) / (h * ss) * 2 - 1
    X, Y = np.meshgrid(xs, ys)
    near = np.stack([X, Y, -np.ones_like(X), np.ones_like(X)], -1) @ inv_viewproj.T
    far = np.stack([X, Y, np.ones_like(X), np.ones_like(X)], -1) @ inv_viewproj.T
    near = near[..., :3] / near[..., 3:]
    far = far[..., :3] / far[..., 3:]
    d = far - near
    return near, d / np.linalg.norm(d, axis=-1, keepdims=True)


def sheets(view, inv_viewproj, w, h, frame, cam_x, ss=1):
    """Per pixel: the sheets' planar camera depths (K, H, W) and premultiplied RGBA (K, H, W, 4), front to back."""
    o, d = pixel_rays(inv_viewproj, w, h, ss)
    depth, rgba = [], []
    for k, y in enumerate(SHEET_Y):
        t = (y - o[..., 1]) / d[..., 1]
        p = o + t[..., None] * d
        zc = -(np.concatenate([p, np.ones(p.shape[:-1] + (1,))], -1) @ view.T)[..., 2]
        c = sheet_colour(k, frame, cam_x, p[..., 0])
        depth.append(zc)
        rgba.append(np.concatenate([c * SHEET_A, np.full(c.shape[:-1] + (1,), SHEET_A)], -1))
    order = np.argsort(np.stack(depth), axis=0)
    depth = np.take_along_axis(np.stack(depth), order, 0)
    rgba = np.take_along_axis(np.stack(rgba), order[..., None], 0)
    return depth, rgba


def split_blend(depth, rgba, split):
    """Front-to-back blend of layers split at per-pixel depth `split`: (front, behind, full, median depth).
    front + (1 - front.a) * behind == full; behind is blended from transmittance 1 (its own layer)."""
    shape = depth.shape[1:]
    front, behind, full = (np.zeros(shape + (4,)) for _ in range(3))
    zmed = np.full(shape, FAR)
    for k in range(depth.shape[0]):
        is_front = depth[k] < split
        for acc, use in ((front, is_front), (behind, ~is_front), (full, np.ones_like(is_front))):
            add = (1 - acc[..., 3:4]) * rgba[k]
            acc += np.where(use[..., None], add, 0)
        crossed = (full[..., 3] >= 0.5) & (zmed == FAR)
        zmed[crossed] = depth[k][crossed]
    return front, behind, full, zmed


def over(fg, bg):
    return fg + (1 - fg[..., 3:4]) * bg


def raster_depth(tris_world, view, proj, w, h, ss=1):
    """Planar camera depth of the nearest triangle at each (sub-)pixel centre, FAR where none; rows bottom-up.
    tris_world: (m, 3, 3). Triangles with a vertex behind the near plane are skipped (enough for this probe)."""
    W, H = w * ss, h * ss
    zbuf = np.full((H, W), FAR)
    v = np.concatenate([tris_world, np.ones(tris_world.shape[:2] + (1,))], -1)
    cam = v @ view.T
    clip = cam @ proj.T
    for tri in range(len(v)):
        wc = clip[tri, :, 3]
        if np.any(wc <= 1e-6):
            continue
        sx = (clip[tri, :, 0] / wc * 0.5 + 0.5) * W
        sy = (clip[tri, :, 1] / wc * 0.5 + 0.5) * H
        x0, x1 = max(int(np.floor(sx.min())), 0), min(int(np.ceil(sx.max())), W - 1)
        y0, y1 = max(int(np.floor(sy.min())), 0), min(int(np.ceil(sy.max())), H - 1)
        if x0 > x1 or y0 > y1:
            continue
        X, Y = np.meshgrid(np.arange(x0, x1 + 1) + 0.5, np.arange(y0, y1 + 1) + 0.5)
        den = (sy[1] - sy[2]) * (sx[0] - sx[2]) + (sx[2] - sx[1]) * (sy[0] - sy[2])
        if abs(den) < 1e-12:
            continue
        b0 = ((sy[1] - sy[2]) * (X - sx[2]) + (sx[2] - sx[1]) * (Y - sy[2])) / den
        b1 = ((sy[2] - sy[0]) * (X - sx[2]) + (sx[0] - sx[2]) * (Y - sy[2])) / den
        b2 = 1 - b0 - b1
        inside = (b0 >= 0) & (b1 >= 0) & (b2 >= 0)
        inv_w = b0 / wc[0] + b1 / wc[1] + b2 / wc[2]  # perspective-correct: 1/w is affine in screen space
        z = np.where(inside, 1.0 / np.maximum(inv_w, 1e-12), FAR)  # w == planar depth for a perspective camera
        sub = zbuf[y0:y1 + 1, x0:x1 + 1]
        np.minimum(sub, z, out=sub)
    return zbuf


def dilate_depth(z):
    """Edge pixels whose centre misses the mesh still carry its anti-aliased (filter-spread) colour: give every
    empty pixel the depth of a covered neighbour (a 4-neighbour first, the nearest of them; else a diagonal one),
    so the split there is at the mesh too. Pixels no mesh reaches keep FAR (there the split changes nothing)."""
    p = np.pad(z, 1, constant_values=FAR)
    h, w = z.shape

    def nb(offsets):
        return np.min([p[1 + dy:h + 1 + dy, 1 + dx:w + 1 + dx] for dy, dx in offsets], axis=0)
    four = nb(((-1, 0), (1, 0), (0, -1), (0, 1)))
    diag = nb(((-1, -1), (-1, 1), (1, -1), (1, 1)))
    return np.where(z < FAR, z, np.where(four < FAR, four, diag))


# ---- camera model of the checker: Blender's pinhole camera rebuilt from the settings (no bpy) ----
def camera_matrices(frame, w, h):
    """view (world->camera) and OpenGL projection for frame's keyframed camera; sensor_fit HORIZONTAL, shift_x in
    units of the image width, clip 0.1..100."""
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # rotation_euler (90, 0, 0): -Z looks along +Y
    c2w[:3, 3] = (CAM_X[frame], CAM_Y, 0.0)
    view = np.linalg.inv(c2w)
    n, f = 0.1, 100.0
    half_w = n * SENSOR / (2 * LENS)
    half_h = half_w * h / w
    dx = SHIFT_X * 2 * half_w
    l, r, b, t = -half_w + dx, half_w + dx, -half_h, half_h
    proj = np.array([[2 * n / (r - l), 0, (r + l) / (r - l), 0], [0, 2 * n / (t - b), (t + b) / (t - b), 0],
                     [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)], [0, 0, -1, 0]])
    return view, proj


def world_triangles():
    out = []
    for kind, centre, size, rot, _ in MESHES.values():
        v, t = mesh_geometry(kind, centre, size, rot)
        out.append(v[t])
    return np.concatenate(out)


# =====================================  Blender side  =====================================
def _bpy():
    import bpy
    return bpy


def version():
    return tuple(_bpy().app.version[:2])


def eevee_id():
    return "BLENDER_EEVEE_NEXT" if version() < (5, 0) else "BLENDER_EEVEE"


def compositor_tree(scene, create=False):
    """4.2-4.5: scene.use_nodes + scene.node_tree (a Composite node is the output).
    5.0+: scene.compositing_node_group, a CompositorNodeTree from bpy.data.node_groups (a Group Output is)."""
    bpy = _bpy()
    if hasattr(scene, "compositing_node_group"):
        if create and scene.compositing_node_group is None:
            scene.compositing_node_group = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        return scene.compositing_node_group
    if create:
        scene.use_nodes = True
    return scene.node_tree


IMAGES = ("gs_front", "gs_behind", "gs_full", "gs_depth")


def build(out, engine):
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = {"EEVEE": eevee_id(), "CYCLES": "CYCLES"}[engine]
    r = scene.render
    r.resolution_x, r.resolution_y = RES
    r.resolution_percentage = PERCENT
    r.film_transparent = True
    r.use_compositing = True
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = 16
        scene.cycles.use_denoising = False
        scene.cycles.pixel_filter_type = "BLACKMAN_HARRIS"
    else:
        scene.eevee.taa_render_samples = 16
    world = bpy.data.worlds.new("Black")
    world.color = (0, 0, 0)
    scene.world = world
    scene.view_layers[0].use_pass_z = True

    for name, (kind, centre, size, rot, colour) in MESHES.items():
        v, t = mesh_geometry(kind, (0, 0, 0), size, 0.0)
        me = bpy.data.meshes.new(name)
        me.from_pydata([tuple(map(float, p)) for p in v], [], [tuple(map(int, f)) for f in t])
        mat = bpy.data.materials.new(name)
        mat.use_nodes = True
        nt = mat.node_tree
        nt.nodes.clear()
        em = nt.nodes.new("ShaderNodeEmission")
        em.inputs["Color"].default_value = (*colour, 1.0)
        em.inputs["Strength"].default_value = 1.0
        mo = nt.nodes.new("ShaderNodeOutputMaterial")
        nt.links.new(em.outputs[0], mo.inputs["Surface"])
        me.materials.append(mat)
        ob = bpy.data.objects.new(name, me)
        ob.location = centre
        ob.rotation_euler = (0, 0, math.radians(rot))
        scene.collection.objects.link(ob)

    cd = bpy.data.cameras.new("Cam")
    cd.lens, cd.sensor_width, cd.sensor_fit, cd.shift_x = LENS, SENSOR, "HORIZONTAL", SHIFT_X
    cd.clip_start, cd.clip_end = 0.1, 100.0
    cam = bpy.data.objects.new("Cam", cd)
    scene.collection.objects.link(cam)
    cam.rotation_euler = (math.radians(90), 0, 0)
    for f, x in CAM_X.items():
        cam.location = (x, CAM_Y, 0.0)
        cam.keyframe_insert("location", frame=f)
    scene.camera = cam
    scene.frame_start, scene.frame_end = 1, 3

    w, h = RES[0] * PERCENT // 100, RES[1] * PERCENT // 100
    for name in IMAGES:
        bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    wire_compositor(scene, out)
    scene.frame_set(3)  # saved away from frame 1: `-f 1` must not see frame 3's camera
    return scene


def wire_compositor(scene, out):
    bpy = _bpy()
    tree = compositor_tree(scene, create=True)
    new5 = hasattr(scene, "compositing_node_group")
    for n in list(tree.nodes):
        tree.nodes.remove(n)
    rl = tree.nodes.new("CompositorNodeRLayers")
    img = {}
    for name in IMAGES:
        node = tree.nodes.new("CompositorNodeImage")
        node.image = bpy.data.images[name]
        img[name] = node

    def alpha_over(bg, fg):
        n = tree.nodes.new("CompositorNodeAlphaOver")
        if new5:  # Background, Foreground, Factor, Type, Straight Alpha
            tree.links.new(bg, n.inputs["Background"])
            tree.links.new(fg, n.inputs["Foreground"])
        else:  # Fac, Image (background), Image_001 (foreground)
            tree.links.new(bg, n.inputs[1])
            tree.links.new(fg, n.inputs[2])
        return n.outputs["Image"]

    mid = alpha_over(img["gs_behind"].outputs["Image"], rl.outputs["Image"])
    result = alpha_over(mid, img["gs_front"].outputs["Image"])

    z = tree.nodes.new("CompositorNodeZcombine")  # the single-depth alternative, for comparison
    if new5:
        tree.links.new(rl.outputs["Image"], z.inputs["A"])
        tree.links.new(rl.outputs["Depth"], z.inputs["Depth A"])
        tree.links.new(img["gs_full"].outputs["Image"], z.inputs["B"])
        tree.links.new(img["gs_depth"].outputs["Image"], z.inputs["Depth B"])
        z.inputs["Use Alpha"].default_value = True
        zout = z.outputs["Result"]
    else:
        tree.links.new(rl.outputs["Image"], z.inputs[0])
        tree.links.new(rl.outputs["Depth"], z.inputs[1])
        tree.links.new(img["gs_full"].outputs["Image"], z.inputs[2])
        tree.links.new(img["gs_depth"].outputs["Image"], z.inputs[3])
        z.use_alpha = True
        zout = z.outputs["Image"]

    if new5:
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        go = tree.nodes.new("NodeGroupOutput")
        tree.links.new(result, go.inputs[0])
    else:
        comp = tree.nodes.new("CompositorNodeComposite")
        comp.use_alpha = True
        tree.links.new(result, comp.inputs["Image"])

    # the splat layers (and what the check needs) as a multilayer EXR per frame: "their own render pass"
    fo = tree.nodes.new("CompositorNodeOutputFile")
    fo.format.file_format = "OPEN_EXR_MULTILAYER"
    fo.format.color_depth = "32"
    items = [("front", img["gs_front"].outputs["Image"]), ("behind", img["gs_behind"].outputs["Image"]),
             ("zcombine", zout), ("render", rl.outputs["Image"]), ("depth", rl.outputs["Depth"])]
    if new5:
        fo.directory = out
        fo.file_name = "layers_"
        for name, src in items:
            it = fo.file_output_items.new("FLOAT" if name == "depth" else "RGBA", name)
            tree.links.new(src, fo.inputs[it.name])
    else:
        fo.base_path = os.path.join(out, "layers_")
        fo.layer_slots.clear()
        for name, src in items:
            fo.layer_slots.new(name)
            tree.links.new(src, fo.inputs[name])


# ---- handlers ----
STATE = {"rendering": False, "events": [], "fills": [], "out": None, "tag": None, "last": None}


def _cam_info(scene, dg=None):
    cam = scene.camera
    e = {"cam_x_orig": round(cam.matrix_world.translation.x, 5)}
    if dg is not None:
        e["cam_x_eval"] = round(cam.evaluated_get(dg).matrix_world.translation.x, 5)
    return e


def _event(name):
    def handler(scene, dg=None):
        e = {"h": name, "t": round(time.perf_counter(), 4), "frame": scene.frame_current,
             "main_thread": threading.current_thread() is threading.main_thread(),
             "dg_mode": getattr(dg, "mode", None), **_cam_info(scene, dg)}
        if name == "render_init":
            STATE["rendering"] = True
            r = scene.render
            e["render"] = {"res": [r.resolution_x, r.resolution_y, r.resolution_percentage],
                           "pixel_aspect": [r.pixel_aspect_x, r.pixel_aspect_y],
                           "border": [r.use_border, r.use_crop_to_border, r.border_min_x, r.border_max_x],
                           "shift": [scene.camera.data.shift_x, scene.camera.data.shift_y],
                           "sensor_fit": scene.camera.data.sensor_fit}
        STATE["events"].append(e)
        if name in ("render_complete", "render_cancel"):
            STATE["rendering"] = False
            dump()
    return handler


def fill(scene, dg):
    """frame_change_post during a render: dg is the render pipeline's depsgraph (mode RENDER), evaluated at the
    frame being rendered (render_pre comes before it, with the camera still at the file's frame in `-a`)."""
    bpy = _bpy()
    if not STATE["rendering"] or dg is None or dg.mode != "RENDER":
        return
    t0 = time.perf_counter()
    se = dg.scene_eval
    r = se.render
    w = r.resolution_x * r.resolution_percentage // 100
    h = r.resolution_y * r.resolution_percentage // 100
    cam = se.camera.evaluated_get(dg)
    proj = np.array(cam.calc_matrix_camera(dg, x=w, y=h, scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y))
    view = np.array(cam.matrix_world.inverted())
    tris = []
    for inst in dg.object_instances:  # the render-visible meshes, evaluated (modifiers, instances)
        ob = inst.object
        if ob.type != "MESH" or not ob.visible_camera:
            continue
        me = ob.data
        me.calc_loop_triangles()
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        idx = np.empty(len(me.loop_triangles) * 3, np.int64)
        me.loop_triangles.foreach_get("vertices", idx)
        m = np.array(inst.matrix_world)
        v = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        tris.append(v[idx.reshape(-1, 3)])
    t1 = time.perf_counter()
    zmesh = raster_depth(np.concatenate(tris), view, proj, w, h) if tris else np.full((h, w), FAR)
    t2 = time.perf_counter()
    split = dilate_depth(zmesh)
    depth, rgba = sheets(view, np.linalg.inv(proj @ view), w, h, se.frame_current,
                         cam.matrix_world.translation.x)
    front, behind, full, zmed = split_blend(depth, rgba, split)
    t3 = time.perf_counter()
    zimg = np.concatenate([np.repeat(zmed[..., None], 3, -1), np.ones_like(zmed)[..., None]], -1)
    layers = [("gs_front", front), ("gs_behind", behind), ("gs_full", full), ("gs_depth", zimg)]
    if r.use_border:  # Blender renders only the border's pixels (disprect = int(border * size))
        x0, x1 = int(r.border_min_x * w), int(r.border_max_x * w)
        y0, y1 = int(r.border_min_y * h), int(r.border_max_y * h)
        if r.use_crop_to_border:  # the render and the compositor are the window's size: so are the images
            layers = [(n, a[y0:y1, x0:x1]) for n, a in layers]
        else:  # full size; splats only where Blender rendered (4.2 composites only the border's pixels anyway)
            keep = np.zeros((h, w, 1))
            keep[y0:y1, x0:x1] = 1
            layers = [(n, a * keep) for n, a in layers]
    for name, arr in layers:
        im = bpy.data.images[name]
        if tuple(im.size) != (arr.shape[1], arr.shape[0]):
            im.scale(arr.shape[1], arr.shape[0])
        im.pixels.foreach_set(arr.astype(np.float32).ravel())
        im.update()
    np.save(os.path.join(STATE["out"], f"zmesh_{STATE['tag']}_{se.frame_current}.npy"), zmesh)
    t4 = time.perf_counter()
    STATE["fills"].append({"frame": se.frame_current, "view_layer": dg.view_layer.name,
                           "main_thread": threading.current_thread() is threading.main_thread(),
                           "cam_x": round(cam.matrix_world.translation.x, 5), "size": [w, h],
                           "ms": {"mesh": round(1e3 * (t1 - t0), 2), "raster": round(1e3 * (t2 - t1), 2),
                                  "splats": round(1e3 * (t3 - t2), 2), "upload": round(1e3 * (t4 - t3), 2)}})


def register(out, tag):
    bpy = _bpy()
    STATE["out"], STATE["tag"] = out, tag
    names = ["render_init", "render_pre", "render_post", "render_write", "render_complete", "render_cancel",
             "frame_change_pre", "frame_change_post"]
    for n in names:
        getattr(bpy.app.handlers, n).append(_event(n))
    bpy.app.handlers.frame_change_post.append(fill)


def dump():
    with open(os.path.join(STATE["out"], f"events_{STATE['tag']}.json"), "w") as f:
        json.dump({"blender": _bpy().app.version_string, "python": sys.version.split()[0],
                   "events": STATE["events"], "fills": STATE["fills"]}, f, indent=1)


def render(out, tag, how):
    bpy = _bpy()
    scene = bpy.context.scene
    register(out, tag)
    if how == "none":
        return  # the binary's -f / -a on the command line render next
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    t0 = time.perf_counter()
    if how in ("still", "crop"):  # F12: RE_RenderFrame at the current frame; the path gets no frame number
        if how == "crop":  # a render border cropped to: the render and the compositor are the window's size
            r = scene.render
            r.use_border, r.use_crop_to_border = True, True
            r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = CROP
        scene.frame_set(2)
        scene.render.filepath = os.path.join(out, f"comp_{tag}_0002")
        bpy.ops.render.render(write_still=True)
    else:  # RE_RenderAnim, the code path of `-f N` (start == end) and `-a`
        scene.frame_start, scene.frame_end = (1, 1) if how == "f1" else (1, 3)
        scene.render.filepath = os.path.join(out, f"comp_{tag}_")
        bpy.ops.render.render(animation=True)
    STATE["events"].append({"h": "wall_s", "t": round(time.perf_counter() - t0, 3)})
    dump()


def gui(out, engine, esc):
    """In Blender's window (run under Xvfb): Render Animation and Render Image as the user starts them
    (INVOKE_DEFAULT: a render job beside the UI's event loop), then quit. With `esc`, an Escape key (xdotool) is
    sent to the render window while frame 2 renders: render_cancel, and what was written by then."""
    bpy = _bpy()
    build(out, engine)
    scene = bpy.context.scene
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    e = engine.lower()
    steps = [(f"{e}_gui_esc", True)] if esc else [(f"{e}_gui_anim", True), (f"{e}_gui_still", False)]
    t_start = {}

    def begin():
        if not steps:
            dump()
            bpy.ops.wm.quit_blender()
            return None
        tag, anim = steps[0]
        STATE["tag"] = tag
        STATE["events"], STATE["fills"] = [], []
        tree = compositor_tree(scene)
        fo = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeOutputFile")
        if hasattr(fo, "file_name"):
            fo.file_name = f"layers_{tag}_"
        else:
            fo.base_path = os.path.join(out, f"layers_{tag}_")
        scene.render.filepath = os.path.join(out, f"comp_{tag}_")
        if not anim:
            scene.frame_set(2)
        win = bpy.context.window_manager.windows[0]
        t_start[tag] = time.perf_counter()
        with bpy.context.temp_override(window=win, area=win.screen.areas[0]):
            r = bpy.ops.render.render("INVOKE_DEFAULT", animation=anim, write_still=not anim)
        STATE["events"].append({"h": "invoke", "t": round(time.perf_counter(), 4), "result": sorted(r),
                                "frame": scene.frame_current, "main_thread": True})
        return None

    def done(scene_, dg=None):
        tag = steps.pop(0)[0] if steps else None
        STATE["events"].append({"h": "wall_s", "t": round(time.perf_counter() - t_start.get(tag, 0), 3)})
        dump()
        bpy.app.timers.register(begin, first_interval=1.0)  # the next step, or quit

    if esc:
        def press_escape(scene_, dg=None):
            if scene_.frame_current == 2 and not STATE.get("esc_sent"):
                STATE["esc_sent"] = True
                import subprocess
                subprocess.Popen(["sh", "-c", "sleep 0.5; xdotool key Escape"])
        bpy.app.handlers.render_pre.append(press_escape)
        scene.eevee.taa_render_samples = 256
        scene.cycles.samples = 4096
    register(out, steps[0][0])
    bpy.app.handlers.render_complete.append(done)
    bpy.app.handlers.render_cancel.append(done)
    bpy.app.timers.register(begin, first_interval=3.0)


def blender_main(argv):
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("--job", required=True, choices=["build", "render", "gui"])
    ap.add_argument("--esc", action="store_true")
    ap.add_argument("--out", required=True)
    ap.add_argument("--engine", default="CYCLES", choices=["CYCLES", "EEVEE"])
    ap.add_argument("--blend")
    ap.add_argument("--tag")
    ap.add_argument("--how", default="none", choices=["none", "f1", "anim", "still", "crop"])
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    bpy = _bpy()
    if a.job == "gui":
        gui(a.out, a.engine, a.esc)
    elif a.job == "build":
        build(a.out, a.engine)
        if a.blend:
            bpy.ops.wm.save_as_mainfile(filepath=a.blend)
    else:
        if a.blend and bpy.data.filepath != a.blend:
            bpy.ops.wm.open_mainfile(filepath=a.blend)
        # a fresh compositor per tag: the File Output writes layers_<tag>_####.exr
        wire_compositor(bpy.context.scene, a.out)
        tree = compositor_tree(bpy.context.scene)
        fo = next(n for n in tree.nodes if n.bl_idname == "CompositorNodeOutputFile")
        if hasattr(fo, "file_name"):
            fo.file_name = f"layers_{a.tag}_"
        else:
            fo.base_path = os.path.join(a.out, f"layers_{a.tag}_")
        if a.how == "none":  # the binary renders from its command line into the scene's output path
            s = bpy.context.scene
            s.render.image_settings.file_format = "OPEN_EXR"
            s.render.image_settings.color_depth = "32"
            s.render.image_settings.color_mode = "RGBA"
            s.render.filepath = os.path.join(a.out, f"comp_{a.tag}_")
        render(a.out, a.tag, a.how)


# =====================================  the check (numpy + OpenImageIO)  =====================================
def read_exr(path):
    """{layer name: (H, W, C) float array, rows bottom-up} of a (multilayer, possibly multi-part) EXR."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise FileNotFoundError(path)
    chans = {}
    sub = 0
    while inp.seek_subimage(sub, 0):
        spec = inp.spec()
        px = np.asarray(inp.read_image(sub, 0, 0, spec.nchannels, oiio.FLOAT))
        px = px.reshape(spec.height, spec.width, spec.nchannels)[::-1]
        for i, name in enumerate(spec.channelnames):
            layer, _, ch = name.rpartition(".")
            chans.setdefault(layer, []).append((ch, px[..., i]))
        sub += 1
    inp.close()
    order = {c: k for k, c in enumerate("RGBAVXYZ")}
    return {layer: np.stack([a for _, a in sorted(cs, key=lambda c: order.get(c[0][-1:], 9))], -1)
            for layer, cs in chans.items()}


def find_layer(layers, key):
    for name, arr in layers.items():
        if name == key or name.startswith(key + ".") or name.split(".")[0] == key:
            return arr
    raise KeyError(f"{key} not in {list(layers)}")


def reference(frame, render_rgba, w, h):
    """The issue's reference: each mesh pixel (Blender's own premultiplied colour and alpha) inserted at its depth
    into the sheets' front-to-back blend. The depth is the geometry's, from this checker's own camera model (not the
    handler's matrices, not Blender's Depth pass): at the pixel centre (the centre sample of a 5x5 supersampled
    raster), and for an edge pixel whose centre misses, the nearest covered sample within 1.5 px."""
    view, proj = camera_matrices(frame, w, h)
    inv = np.linalg.inv(proj @ view)
    alpha = render_rgba[..., 3]
    ss = 5
    zs = raster_depth(world_triangles(), view, proj, w, h, ss)
    zref = zs[ss // 2::ss, ss // 2::ss].copy()
    cov_y, cov_x = np.nonzero(zs < FAR)
    for j, i in zip(*np.nonzero((alpha > 1e-4) & (zref >= FAR))):
        d2 = (cov_x + 0.5 - (i + 0.5) * ss) ** 2 + (cov_y + 0.5 - (j + 0.5) * ss) ** 2
        if len(d2) and d2.min() <= (1.5 * ss) ** 2:
            zref[j, i] = zs[cov_y[np.argmin(d2)], cov_x[np.argmin(d2)]]
    depth, rgba = sheets(view, inv, w, h, frame, CAM_X[frame])
    front, behind, full, _ = split_blend(depth, rgba, zref)
    return over(front, over(render_rgba, behind)), full


def errors(out, ref):
    """Per pixel: max over RGBA of |out - ref|, absolute and relative to the reference pixel (floor 0.05)."""
    a = np.abs(out - ref).max(-1)
    rel = a / np.maximum(np.abs(ref).max(-1), 0.05)
    return {"mean_abs": float(a.mean()), "p99_abs": float(np.percentile(a, 99)), "max_abs": float(a.max()),
            "mean_rel": float(rel.mean()), "p99_rel": float(np.percentile(rel, 99))}


def check_tag(out, tag, frames):
    res = {"tag": tag, "frames": {}, "ok": True, "problems": []}
    ev_path = os.path.join(out, f"events_{tag}.json")
    ev = json.load(open(ev_path)) if os.path.exists(ev_path) else {"events": [], "fills": []}
    res["blender"] = ev.get("blender")
    if tag.endswith("_esc"):  # Escape during an animation: the frames written before it, none of the cancelled one
        frames = [e["frame"] for e in ev["events"] if e["h"] == "render_write"]
        pre = [e["frame"] for e in ev["events"] if e["h"] == "render_pre"]
        cancelled = pre[-1] if pre else None
        res["esc"] = {"written": frames, "cancelled_frame": cancelled,
                      "render_cancel": any(e["h"] == "render_cancel" for e in ev["events"]),
                      "files_of_cancelled": sorted(n for n in os.listdir(out)
                                                   if n.startswith((f"comp_{tag}_{cancelled:04d}",
                                                                    f"layers_{tag}_{cancelled:04d}")))}
        if not res["esc"]["render_cancel"] or res["esc"]["files_of_cancelled"] or cancelled in frames:
            res["ok"] = False
            res["problems"].append(f"Escape: {res['esc']}")
    refs = {}
    for f in frames:
        comp_path = os.path.join(out, f"comp_{tag}_{f:04d}.exr")
        if not os.path.exists(comp_path) and os.path.exists(os.path.join(out, f"comp_{tag}_.exr")):
            comp_path = os.path.join(out, f"comp_{tag}_.exr")  # the GUI's F12 with write_still: no frame number
        lay_path = os.path.join(out, f"layers_{tag}_{f:04d}.exr")
        if not os.path.exists(lay_path) and os.path.exists(os.path.join(out, f"layers_{tag}_.exr")):
            lay_path = os.path.join(out, f"layers_{tag}_.exr")  # 5.x: a still's File Output gets no frame number
            res["file_output_still_unnumbered"] = True
        if not os.path.exists(comp_path) or not os.path.exists(lay_path):
            res["ok"] = False
            res["problems"].append(f"frame {f}: missing {comp_path if not os.path.exists(comp_path) else lay_path}")
            continue
        comp = next(iter(read_exr(comp_path).values()))[..., :4]
        lay = read_exr(lay_path)
        rgba = find_layer(lay, "render")[..., :4]
        bz = find_layer(lay, "depth")[..., 0]
        h, w = comp.shape[:2]
        if tag.endswith("_crop"):  # compare the window of the full frame's reference
            W, H = RES[0] * PERCENT // 100, RES[1] * PERCENT // 100
            x0, x1, y0, y1 = int(CROP[0] * W), int(CROP[1] * W), int(CROP[2] * H), int(CROP[3] * H)
            res["crop"] = {"comp": [w, h], "window": [x1 - x0, y1 - y0], "render": list(rgba.shape[1::-1])}
            if (w, h) != (x1 - x0, y1 - y0) or rgba.shape[:2] != (h, w):
                res["ok"] = False
                res["problems"].append(f"crop: sizes {res['crop']}")
                continue
            whole = np.zeros((H, W, 4))
            whole[y0:y1, x0:x1] = rgba
            ref, full = reference(f, whole, W, H)
            ref, full = ref[y0:y1, x0:x1], full[y0:y1, x0:x1]
            e = errors(comp, ref)
            e["zcombine"] = errors(find_layer(lay, "zcombine")[..., :4], ref)
            res["frames"][f] = e
            if e["mean_rel"] > 0.01 or e["p99_rel"] > 0.03:
                res["ok"] = False
                res["problems"].append(f"crop: error mean {e['mean_rel']:.4f} p99 {e['p99_rel']:.4f}")
            continue
        ref, full = reference(f, rgba, w, h)
        refs[f] = (comp, ref)
        e = errors(comp, ref)
        e["zcombine"] = errors(find_layer(lay, "zcombine")[..., :4], ref)
        front, behind = find_layer(lay, "front")[..., :4], find_layer(lay, "behind")[..., :4]
        e["layers_sum_vs_full"] = float(np.abs(over(front, behind) - full).max())
        # the handler's depth (from Blender's camera matrices in the handler) against Blender's Depth pass
        zp = os.path.join(out, f"zmesh_{tag}_{f}.npy")
        if os.path.exists(zp):
            zm = np.load(zp)
            inner = (rgba[..., 3] >= 0.999) & (zm < FAR)
            d = np.abs(zm[inner] - bz[inner]) / zm[inner]
            e["handler_depth_vs_blender_rel"] = ({"mean": float(d.mean()), "max": float(d.max())}
                                                  if inner.any() else None)
            e["blender_depth_background"] = float(bz[rgba[..., 3] == 0].max()) if (rgba[..., 3] == 0).any() else None
            # alternatives computed here from the same inputs: the split without the 3x3 dilation of the depth,
            # and K depth slices picked per pixel by Blender's Depth pass (a compositor-only design)
            view, proj = camera_matrices(f, w, h)
            depth, srgba = sheets(view, np.linalg.inv(proj @ view), w, h, f, CAM_X[f])
            fr, be, _, _ = split_blend(depth, srgba, zm)
            e["split_no_dilation"] = errors(over(fr, over(rgba, be)), ref)
            lo, hi = float(depth.min()), float(depth.max())
            for k in (4, 8):
                planes = np.linspace(lo, hi, k)
                z_slice = np.where(bz < lo, lo - 1, planes[np.clip(np.searchsorted(planes, bz, "right") - 1, 0, k - 1)])
                fr, be, _, _ = split_blend(depth, srgba, np.where(bz >= FAR / 10, FAR, z_slice + 1e-9))
                e[f"slices_{k}_by_blender_depth"] = errors(over(fr, over(rgba, be)), ref)
        e["aa_edge_pixels"] = int(((rgba[..., 3] > 0.05) & (rgba[..., 3] < 0.95)).sum())
        # occlusion at points of the meshes: in front of every sheet the mesh's own colour shows, behind every
        # sheet the whole blend lies over it
        view, proj = camera_matrices(f, w, h)
        spots = {}
        for name, x, z, in_front in (("Front", -0.95, 0.55, True), ("Back", 0.95, -0.55, False),
                                     ("Tilted", -0.55, 0.0, True), ("Tilted", 0.55, 0.0, False)):
            kind, centre, size, rot, colour = MESHES[name]
            y = centre[1] - size[0] / 2 if kind == "cube" else x * math.tan(math.radians(rot))
            c = proj @ (view @ np.array([x, y, z, 1.0]))
            i, j = int((c[0] / c[3] * 0.5 + 0.5) * w), int((c[1] / c[3] * 0.5 + 0.5) * h)
            mesh = np.array([*colour, 1.0])
            want = mesh if in_front else over(full[j, i], mesh)
            spots[f"{name} x={x:+.2f} {'front' if in_front else 'behind'}"] = {
                "px": [i, j], "got": comp[j, i].round(4).tolist(), "want": want.round(4).tolist(),
                "err": float(np.abs(comp[j, i] - want).max())}
            if np.abs(comp[j, i] - want).max() > 0.02:
                res["ok"] = False
                res["problems"].append(f"frame {f}: {name} at x={x} wrong occlusion")
        e["spots"] = spots
        res["frames"][f] = e
        if e["mean_rel"] > 0.01 or e["p99_rel"] > 0.03:
            res["ok"] = False
            res["problems"].append(f"frame {f}: error mean {e['mean_rel']:.4f} p99 {e['p99_rel']:.4f}")
    # each frame has its own content: frame f's image is far from the other frames' references
    for f, (comp, _) in refs.items():
        for g, (_, ref_g) in refs.items():
            if g != f:
                d = errors(comp, ref_g)["mean_abs"]
                res["frames"][f].setdefault("mean_abs_vs_other_frames", {})[g] = d
                if d < 10 * max(res["frames"][f]["mean_abs"], 1e-4):
                    res["ok"] = False
                    res["problems"].append(f"frame {f} is as close to frame {g}'s reference ({d:.4f})")
    fills = ev.get("fills", [])
    res["fills"] = fills
    res["handlers"] = [(e["h"], e["frame"], e.get("dg_mode"), e.get("main_thread"), e.get("cam_x_orig"),
                        e.get("cam_x_eval")) for e in ev["events"] if e["h"] != "wall_s"]
    res["render_settings"] = next((e["render"] for e in ev["events"] if e["h"] == "render_init"), None)
    walls = [e["t"] for e in ev["events"] if e["h"] == "wall_s"]
    res["wall_s"] = walls[0] if walls else None
    pre = [e["t"] for e in ev["events"] if e["h"] == "render_pre"]
    post = [e["t"] for e in ev["events"] if e["h"] == "render_post"]
    res["frame_s"] = [round(b - a, 3) for a, b in zip(pre, post)]
    for f in frames:
        got = [x for x in fills if x["frame"] == f]
        if not got:
            res["ok"] = False
            res["problems"].append(f"no fill for frame {f}")
        elif abs(got[-1]["cam_x"] - CAM_X[f]) > 1e-4:
            res["ok"] = False
            res["problems"].append(f"frame {f}: the handler saw camera x {got[-1]['cam_x']}, not {CAM_X[f]}")
    return res


def check_main(argv):
    import argparse
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--tags", required=True, help="tag:frames,... e.g. cycles_f1:1,cycles_anim:1-3")
    a = ap.parse_args(argv)
    results = []
    for spec in a.tags.split(","):
        tag, fr = spec.split(":")
        lo, _, hi = fr.partition("-")
        results.append(check_tag(a.out, tag, list(range(int(lo), int(hi or lo) + 1))))
    with open(os.path.join(a.out, "check.json"), "w") as f:
        json.dump(results, f, indent=1, default=float)
    for r in results:
        fr = r["frames"]
        worst = max((v["p99_rel"] for v in fr.values()), default=float("nan"))
        worst_z = max((v["zcombine"]["p99_rel"] for v in fr.values()), default=float("nan"))
        mean = max((v["mean_rel"] for v in fr.values()), default=float("nan"))
        mean_z = max((v["zcombine"]["mean_rel"] for v in fr.values()), default=float("nan"))
        print(f"{TAG}{r['tag']}: {'ok' if r['ok'] else 'FAIL'} Blender {r['blender']} frames {list(fr)} "
              f"split mean {mean:.4f} p99 {worst:.4f} | zcombine mean {mean_z:.4f} p99 {worst_z:.4f} | "
              f"frame s {r['frame_s']} wall {r['wall_s']} {'; '.join(r['problems'])}")
    return 0 if all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    if "--job" in argv and argv[argv.index("--job") + 1] == "check":
        i = argv.index("--job")
        sys.exit(check_main(argv[:i] + argv[i + 2:]))
    blender_main(argv)
