"""Run by a real Blender with its GUI (tests/real_blender/test_gui_overlay.py): the viewport overlay as a user sees it.

    blender --python gui_overlay.py -- --out DIR --room ROOM.PLY [--src CHECKOUT] [--pictures]

The extension is the one installed in this Blender (from the built zip), or, with --src, the package in a checkout
(registered directly: for working on the overlay before a zip exists). The scene: the sample room as a splat
object (its point proxy on, as imported), a grey cube in the room ("Occluder": a mesh in front of splats), a small
red ball of splats ("Blob") in front of a second grey cube ("Backdrop": splats in front of a mesh). From two views
it takes screenshots of the whole X screen (ImageMagick's `import`: Blender's own screenshot operator gives black
images under Xvfb), with steps scheduled by bpy.app.timers so the window draws between them:

  <view>_plain       Show Splats off, Blender's overlays on (grid, helpers)
  <view>_splats      Show Splats on, Blender's overlays on (what a user sees by default)
  <view>_clean       Show Splats on, Blender's overlays off (no grid, no helper geometry can be drawn)
  w_quads            view w (the room's wall from outside) drawn by the plain depth-tested quads (the old draw)

Then real clicks, sent to the X server by xdotool (the window focused first): Shift+right-click on the floor splats
with Show Splats on and off (where the 3D cursor lands against the floor plane z = 0 under that pixel), left clicks
on the splat wall, the red splat ball, a cube and Shift+click on the wall (what gets selected), with screenshots of
the cursor and of the selected ball's origin dot over the splats; a slanted plane in front of the wall shot against
the splats (composite, plain quads) and alone (the room hidden) for its edge; the composite shader checked against
overlay_math.composite on the real overlay layer; File > Import of the room (Show Splats turns on); Update When
Moved: a probe added at a selected sphere, baked, the sphere moved with G and a click, then Ctrl+Z.

It writes DIR/shots.json: per shot the 3D region's place on the screen, the view's matrices, the projected
centres of the test objects, the splat object's bounds corners and the overlay's own coverage image, which the
pytest driver uses to find the splat region; and what each check measured. --pictures also writes the pictures
for docs/img (panel, lit mesh, EEVEE and Cycles renders lit and unlit, cursor, edge, wall). Failures are written
to DIR/error.txt; Blender quits at the end.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import bpy
import numpy as np
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import ARGS, arg, focus as _focus, mod, start, view3d, write_result, xdo as _xdo  # noqa: E402

OUT = os.path.abspath(arg("--out", "/tmp/gui_overlay"))
SRC = arg("--src")
ROOM = arg("--room")
PICTURES = "--pictures" in ARGS
SETTLE = float(arg("--settle", "6"))  # seconds the window gets to draw before a screenshot (llvmpipe is slow)
os.makedirs(OUT, exist_ok=True)

# The views: eye, target. A looks into the room past the Occluder and at the Blob in front of the Backdrop;
# B looks at both from the side, across the floor (where the grid would show); W at the room's wall from outside.
VIEWS = {"a": ((0.2, -2.1, 1.45), (0.35, 1.2, 0.75)), "b": ((-2.3, 1.6, 1.9), (0.7, -0.4, 0.6)),
         "w": ((0.0, -6.0, 1.5), (0.0, 0.5, 1.0))}
FLOOR_VIEW = ((0.6, -0.6, 1.7), (-0.8, 1.2, 0.0))  # the floor point of issue 21 in the middle, clear of the table
FLOOR_POINT = (-0.8, 1.2, 0.0)
WALL_POINT = (-1.2, 2.5, 1.6)  # on the back wall, no test object in front of it in view a
EDGE_CENTRE, EDGE_SIZE, EDGE_ROLL = (-0.45, 0.6, 1.35), 0.5, 12.0  # a plane facing view a, its edges slanted
OCCLUDER = (0.15, 0.75, 0.3)
BLOB, BACKDROP = (0.95, 0.1, 0.8), (1.15, 1.3, 0.8)
BLOB_RGB = (0.9, 0.08, 0.06)

state: dict = {"shots": {}, "log": []}


def log(msg: str) -> None:
    line = f"[gui_overlay {time.strftime('%H:%M:%S')}] {msg}"
    print(line, flush=True)
    state["log"].append(line)


def blob_scene(pkg: str):
    synthetic, scene_mod = mod(pkg, "core.synthetic"), mod(pkg, "core.scene")
    n = 600
    pos = synthetic.fibonacci_sphere(n).astype(np.float32) * np.float32(0.16)
    sh = np.zeros((n, 1, 3), np.float32)
    sh[:, 0] = scene_mod.rgb_to_sh_dc(np.array(BLOB_RGB, np.float32))
    rot = np.zeros((n, 4), np.float32)
    rot[:, 0] = 1.0
    return scene_mod.SplatScene(pos, np.full((n, 3), 0.045, np.float32), rot, np.full(n, 0.95, np.float32), sh,
                                source="blob")


def cube(name: str, location, size: float) -> bpy.types.Object:
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = name
    return obj


def build(pkg: str) -> None:
    splat_object, formats = mod(pkg, "blender.splats.object"), mod(pkg, "core.formats")
    for obj in list(bpy.data.objects):  # the startup file's cube, camera and light
        bpy.data.objects.remove(obj)
    bpy.context.view_layer.update()
    # the sample is stored Z up, as Blender's axes: the room goes in with no axis conversion
    room = formats.read_scene(ROOM or os.path.join(SRC, "samples", "room.ply"))
    try:
        state["room"] = splat_object.create_splat_object(bpy.context, room, "Room")
        state["proxy"] = True
    except Exception as e:  # noqa: BLE001  a Blender whose node API the proxy does not know yet: note it, go on
        log(f"point proxy failed ({type(e).__name__}: {e}); the room has no proxy")
        state["room"] = splat_object.create_splat_object(bpy.context, room, "Room", proxy=False)
        state["proxy"] = False
    state["blob"] = splat_object.create_splat_object(bpy.context, blob_scene(pkg), "Blob", proxy=state["proxy"])
    state["blob"].location = BLOB
    cube("Occluder", OCCLUDER, 0.5)
    cube("Backdrop", BACKDROP, 0.7)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)  # nothing selected: no outlines or origins
    bpy.context.view_layer.objects.active = None
    bpy.context.scene.cursor.location = (0.0, -30.0, 0.0)  # the 3D cursor out of every view
    window, area, space, region = view3d()
    space.show_region_toolbar = False
    space.show_region_ui = False
    space.overlay.show_text = False  # the view name and stats would differ between shots for no reason
    space.show_gizmo = False  # likewise the navigation gizmo
    log(f"Blender {bpy.app.version_string}, Python {sys.version.split()[0]}, window {window.width}x{window.height}, "
        f"region {region.width}x{region.height} at ({region.x}, {region.y})")


def set_view(name: str) -> None:
    eye, target = (Vector(v) for v in VIEWS[name])
    _w, _a, space, region = view3d()
    r3d = space.region_3d
    r3d.view_perspective = "PERSP"
    d = target - eye
    r3d.view_rotation = d.to_track_quat("-Z", "Y")
    r3d.view_location = target
    r3d.view_distance = d.length
    space.lens = 35.0


def set_overlay(show_splats: bool, blender_overlays: bool) -> None:
    _w, _a, space, _r = view3d()
    bpy.context.scene.gs_ibl_overlay.show = show_splats
    space.overlay.show_overlays = blender_overlays


def project(r3d, region, p) -> list[float]:
    """A world point -> pixel (x right, y up) in the region."""
    clip = np.array(r3d.window_matrix) @ np.array(r3d.view_matrix) @ np.array([*p, 1.0])
    ndc = clip[:3] / clip[3]
    return [float((ndc[0] + 1) / 2 * region.width), float((ndc[1] + 1) / 2 * region.height), float(ndc[2])]


def nudge(k: int) -> None:
    _w, _a, space, _r = view3d()
    r3d = space.region_3d
    from mathutils import Quaternion
    r3d.view_rotation = Quaternion((0.0, 0.0, 1.0), math.radians(2.0)) @ r3d.view_rotation
    state["last_nudge"] = time.monotonic()


def record_motion(pkg: str) -> None:
    _w, _a, _s, region = view3d()
    slot = region.as_pointer()
    log_ = [(t, s, ms, dms) for t, sl, s, ms, dms in mod(pkg, "blender.viewport.overlay").draw_log if sl == slot]
    state["motion"] = {"draws": log_, "last_nudge": state["last_nudge"],
                       "resolution": bpy.context.scene.gs_ibl_overlay.resolution_scale}
    log(f"motion: last nudge {state['last_nudge']:.2f}, draws {[(round(t, 2), s) for t, s, _m, _d in log_[-8:]]}")


def record(shot: str, pkg: str) -> None:
    window, area, space, region = view3d()
    r3d = space.region_3d
    path = os.path.join(OUT, f"{shot}.png")
    subprocess.run(["import", "-window", "root", path], check=True)
    overlay = mod(pkg, "blender.viewport.overlay")
    room = state["room"]
    corners = [list(room.matrix_world @ Vector(c)) for c in room.bound_box]
    info = {"png": os.path.basename(path), "window": [window.width, window.height],
            "region": [region.x, region.y, region.width, region.height],
            "view_matrix": [list(r) for r in r3d.view_matrix], "window_matrix": [list(r) for r in r3d.window_matrix],
            "show_splats": bpy.context.scene.gs_ibl_overlay.show, "overlays": space.overlay.show_overlays,
            "points": {k: project(r3d, region, p) for k, p in
                       (("occluder", OCCLUDER), ("blob", BLOB), ("backdrop", BACKDROP))},
            "room_bounds": corners, "room_display": room.display_type,
            "last_draw": {str(k): v for k, v in overlay.last_draw.items()}, "error": overlay.error_text()}
    if bpy.context.scene.gs_ibl_overlay.show:
        scale = bpy.context.scene.gs_ibl_overlay.resolution_scale
        img = mod(pkg, "blender.viewport.overlay_images").splat_image(room, r3d, region.width, region.height, scale, slot="gui-check")
        cov = os.path.join(OUT, f"{shot}_coverage.npy")
        np.save(cov, img.rgba[..., 3])
        info["coverage"], info["coverage_rect"] = os.path.basename(cov), list(img.view.ndc_rect)
    state["shots"][shot] = info
    log(f"shot {shot}: {info['last_draw']} error={info['error']}")


def _fill(fb_size, rgba_lin: np.ndarray) -> None:
    """Write linear RGBA (rows top first) into the bound framebuffer as it is (blend off): what Blender left in the
    overlay layer, for the offscreen composite check."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    overlay_gpu = state["overlay_gpu"]
    info = gpu.types.GPUShaderCreateInfo()
    iface = gpu.types.GPUStageInterfaceInfo("gui_fill_iface")
    iface.smooth("VEC2", "uv")
    info.vertex_in(0, "VEC2", "pos")
    info.vertex_in(1, "VEC2", "texCoord")
    info.vertex_out(iface)
    info.sampler(0, "FLOAT_2D", "image")
    info.fragment_out(0, "VEC4", "fragColor")
    info.vertex_source("void main() { uv = texCoord; gl_Position = vec4(pos, 0.0, 1.0); }")
    info.fragment_source("void main() { fragColor = texelFetch(image, ivec2(gl_FragCoord.xy), 0); }")
    sh = gpu.shader.create_from_info(info)
    tex = overlay_gpu._float_texture(rgba_lin.astype(np.float32), "RGBA32F")
    batch = batch_for_shader(sh, "TRI_FAN", {"pos": ((-1, -1), (1, -1), (1, 1), (-1, 1)),
                                             "texCoord": ((0, 0), (1, 0), (1, 1), (0, 1))})
    gpu.state.blend_set("NONE")
    sh.bind()
    sh.uniform_sampler("image", tex)
    batch.draw(sh)


def shader_check(pkg: str) -> None:
    """The overlay's shaders against their numpy references, drawn into an offscreen buffer exactly as the draw
    handler draws and read back: the plain quads (overlay_math.layer_colour, window_depth) and the composite
    (overlay_math.composite: every branch, on synthetic inputs; the layer given as Blender leaves it)."""
    import gpu
    overlay, om = mod(pkg, "blender.viewport.overlay"), mod(pkg, "blender.viewport.overlay_math")
    overlay_gpu = mod(pkg, "blender.viewport.overlay_gpu")
    state["overlay_mod"], state["om"], state["overlay_gpu"] = overlay, om, overlay_gpu
    w, h = 96, 64
    rng = np.random.default_rng(7)
    rgba = rng.random((h, w, 4)).astype(np.float32) * np.float32(1.5)
    rgba[..., 3] = rng.random((h, w)).astype(np.float32)
    rgba[..., :3] *= rgba[..., 3:]  # premultiplied, some colours above 1
    rgba[:4, :, 3] = 0.0  # uncovered rows
    depth = (0.5 + 9.0 * rng.random((h, w))).astype(np.float32)
    depth[:, :3] = 0.0  # no splat seen
    view = om.overlay_view(om.look_at_view_matrix((0, -3, 1), (0, 0, 1)), om.perspective_matrix(50, w, h, 0.1, 30.0),
                           w, h, 1.0)
    exposure = 0.5
    off = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    with off.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        colour_tex, depth_tex = overlay_gpu.textures(rgba, depth)
        overlay_gpu.draw_quads([(colour_tex, depth_tex, (-1.0, -1.0, 1.0, 1.0),
                             overlay_gpu.shader_params(view, exposure))])
        got = np.array(fb.read_color(0, 0, w, h, 4, 0, "FLOAT").to_list(), np.float32).reshape(h, w, 4)[::-1]
        got_depth = np.array(fb.read_depth(0, 0, w, h).to_list(), np.float32).reshape(h, w)[::-1]
    off.free()
    a = rgba[..., 3]
    lc, la = om.layer_colour(rgba, exposure)
    want = np.where((a >= overlay_gpu.ALPHA_CUT)[..., None], np.concatenate([lc, la[..., None]], -1), 0.0)
    want_depth = np.where(a >= overlay_gpu.OPAQUE_CUT, om.window_depth(depth, view, om.DEPTH_PULL), 1.0)
    state["shader_check"] = {"colour_max_error": float(np.abs(got - want).max()),
                             "depth_max_error": float(np.abs(got_depth - want_depth).max()),
                             "pixels": w * h}
    log(f"shader check: {state['shader_check']}")
    state["composite_check"] = {n: composite_offscreen_check(pkg, n_layers=n) for n in (1, 2, 4)}
    log(f"composite check: {state['composite_check']}")


def composite_offscreen_check(pkg: str, w: int = 80, h: int = 56, n_layers: int = 2) -> dict:
    import gpu
    overlay_gpu = mod(pkg, "blender.viewport.overlay_gpu")
    om = mod(pkg, "blender.viewport.overlay_math")
    srgb = mod(pkg, "core.colour").linear_to_srgb
    rng = np.random.default_rng(11)
    view_m = om.look_at_view_matrix((0.3, -4.0, 2.0), (0.0, 0.0, 0.0))
    win_m = om.perspective_matrix(60.0, w, h, 0.1, 50.0)
    bg = np.array([0.046, 0.047, 0.048])
    # the floor plane's window depth per pixel, through the same inverse the shader uses
    inv = np.linalg.inv(win_m @ view_m)
    eye = np.linalg.inv(view_m)[:3, 3]
    xs = (np.arange(w) + 0.5) / w * 2 - 1
    ys = 1 - (np.arange(h) + 0.5) / h * 2
    far = np.einsum("ij,hwj->hwi", inv, np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], 1.0, 1.0), -1))
    ray = far[..., :3] / far[..., 3:] - eye
    t = np.where(ray[..., 2] < -1e-6, -eye[2] / np.minimum(ray[..., 2], -1e-6), np.inf)
    pts = eye + ray * np.where(np.isfinite(t), t, 0.0)[..., None]
    clip = np.einsum("ij,hwj->hwi", win_m @ view_m, np.concatenate([pts, np.ones((h, w, 1))], -1))
    floor = np.where(np.isfinite(t), 0.5 * clip[..., 2] / clip[..., 3] + 0.5, 1.0)
    kind = rng.integers(0, 6, (h, w))  # 0 background, 1 mesh, 2 mesh edge, 3 grid line, 4 line, 5 line, no depth
    kind[floor >= 1.0] = np.where(kind[floor >= 1.0] == 3, 0, kind[floor >= 1.0])
    cov = np.where(kind == 1, 1.0, np.where(kind == 2, rng.uniform(0.15, 0.85, (h, w)), 0.0))
    depth = np.where(kind == 1, rng.uniform(0.95, 0.99, (h, w)), 1.0)
    depth = np.where((kind == 2) & (rng.random((h, w)) < 0.5), rng.uniform(0.95, 0.99, (h, w)), depth)
    depth = np.where(kind == 3, floor, depth)
    depth = np.where(kind == 4, rng.uniform(0.95, 0.99, (h, w)), depth)
    line = kind >= 3
    la = rng.uniform(0.3, 1.0, (h, w))
    lc = rng.uniform(0.0, 1.0, (h, w, 3))
    o_lin = np.zeros((h, w, 4))
    o_lin[..., :3] = (1.0 - cov)[..., None] * bg
    o_lin[..., :3] = np.where(line[..., None], la[..., None] * lc + (1 - la[..., None]) * o_lin[..., :3],
                              o_lin[..., :3])
    o_lin[..., 3] = np.where(line, la, 0.0)
    o8 = np.empty((h, w, 4), np.uint8)  # as stored: sRGB-encoded colour, linear alpha
    o8[..., :3] = np.round(srgb(o_lin[..., :3]) * 255)
    o8[..., 3] = np.round(o_lin[..., 3] * 255)
    o_dec = np.concatenate([om.decode_overlay(o8)[0], om.decode_overlay(o8)[1][..., None]], -1)
    # two splat layers: window depths around the meshes' (some in front, some behind), coverages of all kinds
    ov_view = om.overlay_view(view_m, win_m, w, h, 1.0)
    layers_px, layers_ref = [], []
    for k in range(n_layers):
        a = rng.choice([0.0, 0.4, 0.8, 1.0], (h, w)).astype(np.float32)
        rgba = np.zeros((h, w, 4), np.float32)
        rgba[..., 3] = a
        rgba[..., :3] = rng.uniform(0, 1.2, (h, w, 3)).astype(np.float32) * a[..., None]
        dist = rng.choice([0.6, 1.5, 3.0, 8.0], (h, w)).astype(np.float32) + np.float32(0.01 * k)
        wd = om.window_depth(dist, ov_view, om.DEPTH_PULL)
        rgb, al = om.layer_colour(rgba, 0.0)
        layers_px.append(overlay_gpu.textures(rgba, dist))
        layers_ref.append((rgb, al, wd))
    discs = [(20.5, 30.5, 9.0), (60.0, 12.0, 5.0)]
    ref, written = om.composite(o8, depth, layers_ref, bg, use_coverage=True, grid=(view_m, win_m, (0, 0, 1)),
                                discs=discs)
    want = np.where(written[..., None], ref, o_dec)
    params = overlay_gpu.composite_params(win_m, view_m, w, h, {"kind": "SINGLE_COLOR", "high": tuple(bg),
                                                            "low": tuple(bg), "use_coverage": True},
                                      (0.0, 0.0, 1.0), discs)
    snap = []
    for lo, hi in ((0, 1), (2, 3)):  # as the draw handler packs them: r + 256 g, b + 256 a (rows bottom first)
        v = np.ascontiguousarray((o8[::-1, :, lo].astype(np.float32) + 256.0 * o8[::-1, :, hi]).ravel(), np.float32)
        snap.append(gpu.types.GPUTexture((w, h), format="R32F", data=gpu.types.Buffer("FLOAT", v.size, v)))
    dtex = overlay_gpu._float_texture(depth.astype(np.float32), "R32F")
    off = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    with off.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        _fill((w, h), o_dec)
        overlay_gpu.draw_composite(tuple(snap), dtex, layers_px, (-1.0, -1.0, 1.0, 1.0),
                               overlay_gpu.shader_params(ov_view, 0.0), params)
        got = np.array(fb.read_color(0, 0, w, h, 4, 0, "FLOAT").to_list(), np.float32).reshape(h, w, 4)[::-1]
    off.free()
    err = np.abs(got - want).max(-1)
    np.savez(os.path.join(OUT, "composite_offscreen.npz"), got=got, want=want, kind=kind, written=written)
    kinds = {name: int(((kind == i) & written).sum()) for i, name in
             enumerate(("background", "mesh", "edge", "grid", "line", "line_no_depth"))}
    return {"max_error": float(err.max()), "over_1e-3": int((err > 1e-3).sum()), "pixels": w * h,
            "written": int(written.sum()), "kinds_written": kinds,
            "in_discs": int((om.disc_mask(w, h, discs) & line).sum())}


def _pixel(point) -> tuple[int, int]:
    """The region pixel a world point projects to, rounded (the mouse lands on whole pixels)."""
    window, _a, space, region = view3d()
    x, y, _z = project(space.region_3d, region, point)
    return int(round(x)), int(round(y))


def click(x: int, y: int, button: int = 1, shift: bool = False) -> None:
    """A real click at region pixel (x, y): xdotool moves the X pointer there and presses the button."""
    window, _a, _s, region = view3d()
    _focus()
    _xdo("mousemove", "--sync", region.x + x, window.height - 1 - (region.y + y))
    if shift:
        _xdo("keydown", "shift")
    _xdo("click", button)
    if shift:
        _xdo("keyup", "shift")
    state["last_click"] = (x, y)


def floor_truth(x: int, y: int) -> list[float]:
    """Where the ray of region pixel (x, y) (Blender's convention, event.mval) meets the floor plane z = 0."""
    om = state["om"]
    _w, _a, space, region = view3d()
    r3d = space.region_3d
    o, d = om.mouse_ray(np.array(r3d.view_matrix), np.array(r3d.window_matrix), region.width, region.height, x, y)
    return list(map(float, o + d * (-o[2] / d[2])))


def cursor_click(tag: str, pkg: str) -> None:
    bpy.context.scene.cursor.location = (0.0, -30.0, 0.0)  # away from the floor point: where a fall-back lands
    x, y = _pixel(FLOOR_POINT)
    state.setdefault("clicks", {})[tag] = {"pixel": [x, y], "truth": floor_truth(x, y)}
    click(x, y, button=3, shift=True)


def cursor_record(tag: str, pkg: str) -> None:
    c = state["clicks"][tag]
    c["cursor"] = list(map(float, bpy.context.scene.cursor.location))
    c["error_m"] = float(np.linalg.norm(np.array(c["cursor"]) - np.array(c["truth"])))
    c["pick"] = dict(mod(pkg, "blender.viewport.picking").last_pick)
    log(f"cursor {tag}: {c}")


def select_click(tag: str, point, shift: bool = False) -> None:
    x, y = _pixel(point)
    state.setdefault("selects", {})[tag] = {"pixel": [x, y], "shift": shift}
    click(x, y, button=1, shift=shift)


def select_record(tag: str, pkg: str) -> None:
    active = bpy.context.view_layer.objects.active
    rec = state["selects"][tag]
    rec.update(selected=sorted(o.name for o in bpy.context.selected_objects),
               active=active.name if active else None, pick=dict(mod(pkg, "blender.viewport.picking").last_pick))
    log(f"select {tag}: {rec}")


def deselect_all() -> None:
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    bpy.context.view_layer.objects.active = None


def theme_info(pkg: str) -> None:
    prefs = bpy.context.preferences
    t = prefs.themes[0].view_3d
    state["theme"] = {"object_active": list(t.object_active), "object_selected": list(t.object_selected),
                      "origin_size": t.object_origin_size,
                      "widget_unit": round(18.0 * prefs.system.ui_scale) + 2 * prefs.system.pixel_size}


def _look(eye, target) -> None:
    _w, _a, space, _r = view3d()
    r3d = space.region_3d
    r3d.view_perspective = "PERSP"
    d = Vector(target) - Vector(eye)
    r3d.view_rotation = d.to_track_quat("-Z", "Y")
    r3d.view_location = Vector(target)
    r3d.view_distance = d.length
    space.lens = 35.0


def edge_plane(pkg: str) -> None:
    """A plane facing view a, rolled by EDGE_ROLL degrees: straight slanted edges in front of the splat wall."""
    eye = Vector(VIEWS["a"][0])
    bpy.ops.mesh.primitive_plane_add(size=EDGE_SIZE, location=EDGE_CENTRE)
    plane = bpy.context.active_object
    plane.name = "Edge"
    facing = (eye - Vector(EDGE_CENTRE)).to_track_quat("Z", "Y")
    from mathutils import Quaternion
    plane.rotation_mode = "QUATERNION"
    plane.rotation_quaternion = facing @ Quaternion((0.0, 0.0, 1.0), math.radians(EDGE_ROLL))
    deselect_all()
    bpy.context.view_layer.update()
    state["edge"] = plane


def edge_record(shot: str, pkg: str) -> None:
    """Screenshot plus the plane's corners in region pixels."""
    record(shot, pkg)
    _w, _a, space, region = view3d()
    plane = state["edge"]
    corners = [plane.matrix_world @ Vector((sx * EDGE_SIZE / 2, sy * EDGE_SIZE / 2, 0.0))
               for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    state["shots"][shot]["edge_corners"] = [project(space.region_3d, region, c)[:2] for c in corners]
    state["shots"][shot]["draw"] = {str(k): v for k, v in mod(pkg, "blender.viewport.overlay").last_draw.items()}


def composite_capture(pkg: str) -> None:
    overlay = mod(pkg, "blender.viewport.overlay")
    overlay.capture.clear()
    overlay.capture["next"] = True
    view3d()[1].tag_redraw()


def composite_real_check(pkg: str) -> None:
    """The composite as drawn in the viewport against overlay_math.composite on the same overlay layer, depth and
    splat image (Resolution 1: the image's pixels are the region's)."""
    overlay, om = mod(pkg, "blender.viewport.overlay"), mod(pkg, "blender.viewport.overlay_math")
    srgb = mod(pkg, "core.colour").linear_to_srgb
    cap = overlay.capture
    if "out" not in cap:
        state["composite_real"] = {"error": "no capture (the composite did not run)"}
        return
    _w, _a, space, region = view3d()
    r3d = space.region_3d
    w, h = cap["size"]
    p = cap["params"]
    layers = []
    for name in cap["objects"]:
        img = mod(pkg, "blender.viewport.overlay_images").splat_image(bpy.data.objects[name], r3d, w, h, 1.0, region.as_pointer())
        rgb, a = om.layer_colour(img.rgba, bpy.context.scene.gs_ibl_overlay.exposure)
        layers.append((rgb, a, om.window_depth(img.depth, img.view, om.DEPTH_PULL)))
    view_m, win_m = np.array(r3d.view_matrix), np.array(r3d.window_matrix)
    grid = (view_m, win_m, p["grid_normal"][:3]) if p["grid_normal"][3] > 0 else None
    colour, depth, out = cap["colour"][::-1], cap["depth"][::-1], cap["out"][::-1]
    bg = om.viewport_background("SINGLE_COLOR" if p["bg_high"][3] == 0 else
                                ("LINEAR" if p["bg_high"][3] == 1 else "RADIAL"), p["bg_high"][:3], p["bg_low"][:3],
                                w, h)
    ref, written = om.composite(colour, depth, layers, bg, use_coverage=p["use_coverage"] > 0.5, grid=grid,
                                discs=p["discs"])
    ref8 = np.concatenate([srgb(ref[..., :3]) * 255.0, np.clip(ref[..., 3:], 0, 1) * 255.0], -1)
    ref8 = np.where(written[..., None], ref8, colour.astype(np.float64))
    diff = np.abs(ref8 - out.astype(np.float64)).max(-1)
    line = colour[..., 3] >= 2
    state["composite_real"] = {"max_diff_8bit": float(diff.max()), "over_2": int((diff > 2).sum()),
                               "pixels": int(w * h), "written": int(written.sum()), "line_pixels": int(line.sum()),
                               "discs": len(p["discs"]), "grid": grid is not None, "objects": cap["objects"],
                               "use_coverage": p["use_coverage"] > 0.5}
    log(f"composite in the viewport: {state['composite_real']}")


def import_check(pkg: str):
    """File > Import of a splat file turns Show Splats on: the imported splats are drawn at once."""
    settings = bpy.context.scene.gs_ibl_overlay

    def run():
        settings.show = False
        before = set(bpy.data.objects)
        r = bpy.ops.gs_ibl.import_splats(filepath=ROOM or os.path.join(SRC, "samples", "room.ply"))
        new = [o for o in bpy.data.objects if o not in before]
        state["import"] = {"result": sorted(r), "show_after": bool(settings.show), "new": [o.name for o in new]}
        view3d()[1].tag_redraw()

    def drawn():
        overlay = mod(pkg, "blender.viewport.overlay")
        _w, _a, _s, region = view3d()
        d = overlay.last_draw.get(region.as_pointer(), {})
        state["import"]["drawn"] = d.get("objects_drawn", [])
        log(f"import: {state['import']}")
    yield 0.5, run
    yield SETTLE, drawn


def _pixels(img) -> np.ndarray:
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    return px


def auto_update_check(pkg: str):
    """Update When Moved: a probe added at a selected mesh follows it; moving the mesh in the GUI (G, mouse, click)
    re-bakes once, and Ctrl+Z after it re-bakes nothing and leaves the report of the World in use."""
    bake = mod(pkg, "blender.lighting.auto_update")  # its count of automatic bakes
    rec = state.setdefault("auto", {})
    settings = bpy.context.scene.gs_ibl_overlay

    def setup():
        settings.show = True
        _look(*VIEWS["a"])
        deselect_all()
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.2, location=(-0.5, 0.3, 0.45))
        sphere = bpy.context.active_object
        sphere.name = "Moved"
        state["moved"] = sphere
        r = bpy.ops.gs_ibl.add_probe()
        probe = bpy.context.active_object
        s = probe.gs_ibl_probe
        s.splats = state["room"]
        s.face_size = 32
        s.irradiance_size = 16
        s.auto_update = True
        s.update_interval = 0.5
        if hasattr(s, "lighting"):
            s.lighting = "WORLD"  # the World probe only: no per-mesh probes or grids to bake on llvmpipe
        rec.update(add=sorted(r), parent=probe.parent.name if probe.parent else None)
        state["probe"] = probe
        state["probe_name"] = probe.name
        rec["bake"] = sorted(bpy.ops.gs_ibl.bake_probe())
        rec["report_1"] = s.last_report
        rec["auto_bakes_0"] = bake.auto_bakes
        img = s.irradiance_image
        state["pixels_1"] = _pixels(img) if img is not None else None
        deselect_all()
        sphere.select_set(True)
        bpy.context.view_layer.objects.active = sphere
        rec["location_0"] = list(map(float, sphere.location))
        # what the script made so far is one undo step (operators run from a script push none), so Ctrl+Z
        # after the move goes back to here, not to the startup file
        bpy.ops.ed.undo_push(message="GUI check: probe baked")

    def move():
        _window, _a, _s, region = view3d()
        x, y = _pixel(bpy.data.objects["Moved"].location)
        _focus()
        window = view3d()[0]
        sx, sy = region.x + x, window.height - 1 - (region.y + y)
        _xdo("mousemove", "--sync", sx, sy)
        _xdo("key", "g")
        state["g_at"] = (sx, sy)

    def drag():
        sx, sy = state["g_at"]
        for k in range(1, 7):
            _xdo("mousemove", "--sync", sx + 12 * k, sy)
        _xdo("click", 1)

    def after_move():
        probe = bpy.data.objects[state["probe_name"]]
        s = probe.gs_ibl_probe
        rec.update(location_1=list(map(float, bpy.data.objects["Moved"].location)), auto_bakes_1=bake.auto_bakes,
                   report_2=s.last_report, probe_world_1=list(map(float, probe.matrix_world.translation)))
        log(f"auto update after the move: {rec}")

    def undo():
        _focus()
        _xdo("key", "ctrl+z")

    def after_undo():
        probe = bpy.data.objects.get(state["probe_name"])  # undo replaced every datablock: look them up again
        s = probe.gs_ibl_probe if probe is not None else None
        img = s.irradiance_image if s is not None else None
        world = s.world if s is not None else None
        stamps = {"world": world.get("gs_ibl_bake") if world is not None else None,
                  "irradiance": img.get("gs_ibl_bake") if img is not None else None,
                  "radiance": s.radiance_image.get("gs_ibl_bake") if s is not None and s.radiance_image else None}
        px = _pixels(img) if img is not None else None
        p1 = state.get("pixels_1")
        moved = bpy.data.objects.get("Moved")
        rec.update(location_2=list(map(float, moved.location)) if moved else None, auto_bakes_2=bake.auto_bakes,
                   report_3=s.last_report if s is not None else None, stamps=stamps,
                   scene_world_is_probe_world=bool(world is not None and bpy.context.scene.world == world),
                   pixels_equal_bake_1=bool(px is not None and p1 is not None and px.shape == p1.shape
                                            and np.array_equal(px, p1)))
        log(f"auto update after Ctrl+Z: {rec}")

    yield 0.5, setup
    yield SETTLE, move
    yield 1.5, drag
    yield 8.0, after_move
    yield 0.5, undo
    yield 8.0, after_undo


def set_composite(on: bool, pkg: str) -> None:
    mod(pkg, "blender.viewport.overlay").use_composite = on
    view3d()[1].tag_redraw()


def _burst() -> float | None:
    if not state.get("burst"):
        return None
    view3d()[1].tag_redraw()
    return 0.02


def redraw_burst(on: bool) -> None:
    state["burst"] = on
    if on and not bpy.app.timers.is_registered(_burst):
        bpy.app.timers.register(_burst, first_interval=0.02)


def keep_draw_log(pkg: str, tag: str) -> None:
    """The overlay's recent draws (time, scale, render ms, draw ms) of the 3D region, under a tag."""
    _w, _a, _s, region = view3d()
    slot = region.as_pointer()
    entries = [(t, s, ms, dms) for t, sl, s, ms, dms in mod(pkg, "blender.viewport.overlay").draw_log if sl == slot]
    state.setdefault("draw_log", {})[tag] = entries
    mod(pkg, "blender.viewport.overlay").draw_log.clear()


def steps(pkg: str):
    """The script: (seconds to wait before it, what to do), one after the other."""
    yield 1.0, lambda: shader_check(pkg)
    yield 1.0, lambda: build(pkg)
    yield 0.5, lambda: theme_info(pkg)
    for name in VIEWS:
        yield 1.0, lambda name=name: (set_view(name), set_overlay(False, True))
        yield SETTLE, lambda name=name: record(f"{name}_plain", pkg)
        yield 0.5, lambda: set_overlay(True, True)
        yield SETTLE * 2, lambda name=name: record(f"{name}_splats", pkg)
        yield 0.5, lambda: set_overlay(True, False)
        yield SETTLE, lambda name=name: record(f"{name}_clean", pkg)
    yield 0.5, lambda: (set_overlay(True, True), set_composite(False, pkg))
    yield SETTLE, lambda: record("w_quads", pkg)  # the old draw: grid lines in the wall's lower band
    yield 0.5, lambda: set_composite(True, pkg)
    # orbit a little (a view change every 0.3 s), then keep still: coarse frames while moving, then one timed
    # redraw at the full Resolution with no event at all
    yield 0.5, lambda: set_view("a")
    for k in range(5):
        yield 0.3, lambda k=k: nudge(k)
    yield 2.5 + SETTLE, lambda: record_motion(pkg)
    # what a redraw of an unchanged view costs, the composite and the plain quads: the draw handler's own time,
    # and redraws per second while a timer asks for one every 20 ms (the window's whole redraw on llvmpipe)
    yield 0.5, lambda: keep_draw_log(pkg, "before")
    for tag in ("composite", "quads"):
        yield 0.5, lambda tag=tag: (set_composite(tag == "composite", pkg), redraw_burst(True))
        yield 12.0, lambda tag=tag: (redraw_burst(False), keep_draw_log(pkg, tag))
    yield 0.5, lambda: set_composite(True, pkg)
    # the 3D cursor on the floor splats by a real Shift+right-click, then the same with Show Splats off
    yield 0.5, lambda: (_look(*FLOOR_VIEW), set_overlay(True, True))
    yield SETTLE * 2, lambda: cursor_click("splats", pkg)
    yield 2.0 + SETTLE, lambda: (cursor_record("splats", pkg), record("cursor_splats", pkg))
    yield 0.5, lambda: set_overlay(False, True)
    yield SETTLE, lambda: record("cursor_plain", pkg)  # Blender's own cursor at the same place, no splats
    yield 0.5, lambda: cursor_click("plain", pkg)
    yield 2.0 + SETTLE, lambda: cursor_record("plain", pkg)
    # clicks that select: the wall (the room), the red ball (the Blob, in front of a cube), a cube, Shift+wall
    yield 0.5, lambda: (set_view("a"), set_overlay(True, True), deselect_all())
    yield SETTLE * 2, lambda: select_click("wall", WALL_POINT)
    yield 3.0, lambda: (select_record("wall", pkg), select_click("blob", BLOB))
    yield 3.0, lambda: select_record("blob", pkg)
    yield SETTLE, lambda: record("origin_splats", pkg)
    yield 0.5, lambda: select_click("occluder", OCCLUDER)
    yield 3.0, lambda: (select_record("occluder", pkg), select_click("wall_shift", WALL_POINT, shift=True))
    yield 3.0, lambda: select_record("wall_shift", pkg)
    # a straight slanted edge in front of the wall: composite, plain quads, and the plane alone (room hidden)
    yield 0.5, lambda: (deselect_all(), edge_plane(pkg), set_overlay(True, False))
    yield SETTLE * 2, lambda: edge_record("edge_splats", pkg)
    yield 0.5, lambda: set_composite(False, pkg)
    yield SETTLE, lambda: edge_record("edge_quads", pkg)
    yield 0.5, lambda: (set_composite(True, pkg), set_overlay(False, False),
                        [state[k].hide_set(True) for k in ("room", "blob")])
    yield SETTLE, lambda: edge_record("edge_alone", pkg)
    yield 0.5, lambda: ([state[k].hide_set(False) for k in ("room", "blob")], set_overlay(True, True),
                        setattr(bpy.context.scene.gs_ibl_overlay, "resolution_scale", 1.0),
                        state["blob"].select_set(True))
    # the composite in the viewport against its numpy reference (grid, outline, origins and cursor in view)
    yield SETTLE * 2, lambda: composite_capture(pkg)
    yield SETTLE, lambda: composite_real_check(pkg)
    yield 0.5, lambda: setattr(bpy.context.scene.gs_ibl_overlay, "resolution_scale", 0.5)
    yield from auto_update_check(pkg)
    yield from import_check(pkg)
    if PICTURES:
        yield from pictures(pkg)


PROBE = (0.0, 0.45, 0.9)
HEADER_ROWS = 60  # the 3D region's top rows under the header
TAB_FROM_TOP = 240  # where the GS-IBL tab (the fifth: Item, Tool, View, Animation, GS-IBL) sits in the sidebar
PICTURE_EYE, PICTURE_TARGET = (0.35, -0.95, 0.95), (0.05, 0.5, 0.35)
VIEW_EYE = (0.9, -1.9, 1.5)  # the viewport picture: further back, the probe and the room around the meshes


def _screen() -> np.ndarray:
    """The X screen as float RGB, row 0 at the top."""
    path = os.path.join(OUT, "screen.png")
    subprocess.run(["import", "-window", "root", path], check=True)
    return _load_rgb(path)


def _load_rgb(path: str) -> np.ndarray:
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3]


def _save_png(rgb: np.ndarray, name: str, scale: float = 1.0) -> None:
    """Write pixels as read from a PNG (sRGB values, row 0 at the top) as DIR/pictures/<name>.png, optionally
    scaled (docs pictures stay under ~300 KB)."""
    h, w = rgb.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=False)
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = rgb[::-1]
    img.pixels.foreach_set(px.ravel())
    if scale != 1.0:
        img.scale(int(w * scale), int(h * scale))
    img.filepath_raw = os.path.join(OUT, "pictures", f"{name}.png")
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    log(f"picture {name}: {w}x{h}")


def _crop(screen: np.ndarray, region) -> np.ndarray:
    top = screen.shape[0] - region.y - region.height
    return screen[top:top + region.height, region.x:region.x + region.width]


def _picture_scene(pkg: str) -> None:
    """The test objects make way for a white sphere and a grey monkey lit by a probe baked in the room."""
    for name in ("Blob", "Occluder", "Backdrop"):
        bpy.data.objects.remove(bpy.data.objects[name])
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(-0.25, 0.55, 0.3), segments=48, ring_count=24)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    bpy.ops.mesh.primitive_monkey_add(size=0.5, location=(0.4, 0.45, 0.32), rotation=(0.0, 0.0, math.radians(200)))
    monkey = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    for obj, grey in ((sphere, 0.8), (monkey, 0.5)):
        mat = bpy.data.materials.new(obj.name)
        bsdf = mod(pkg, "blender.common.compat").node_tree(mat).nodes.get("Principled BSDF")
        bsdf.inputs["Base Color"].default_value = (grey, grey, grey, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.6
        obj.data.materials.append(mat)
    state["meshes"] = (sphere, monkey)
    bpy.context.scene.cursor.location = PROBE
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size = 128
    probe.gs_ibl_probe.keep_background = False  # the renders show the baked room behind the meshes
    state["probe"] = probe
    bpy.context.scene.cursor.location = (0.0, -30.0, 0.0)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    d = Vector(PICTURE_TARGET) - Vector(PICTURE_EYE)
    cam.location = PICTURE_EYE
    cam.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = 30.0
    bpy.context.scene.camera = cam


def _render(engine: str, name: str) -> None:
    scene = bpy.context.scene
    names = ["BLENDER_EEVEE_NEXT", "BLENDER_EEVEE"] if engine == "EEVEE" else ["CYCLES"]
    if engine == "CYCLES":
        import addon_utils
        addon_utils.enable("cycles", default_set=True)  # a user directory made with --factory-startup lacks it
    allowed = scene.render.bl_rna.properties["engine"].enum_items.keys()
    scene.render.engine = next((n for n in names if n in allowed), names[-1])
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 360, 270, 100
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    if engine == "EEVEE":
        scene.eevee.taa_render_samples = 16
    else:
        scene.cycles.samples = 128
        scene.cycles.use_denoising = True
    scene.render.filepath = os.path.join(OUT, "pictures", f"{name}.png")
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    log(f"render {name}: {time.perf_counter() - t:.1f} s")


def _unlit_world() -> None:
    world = bpy.data.worlds.get("Unlit") or bpy.data.worlds.new("Unlit")
    world.color = (0.05, 0.05, 0.05)
    if world.node_tree is not None:
        bg = world.node_tree.nodes.get("Background")
        if bg is not None:
            bg.inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    bpy.context.scene.world = world


def _shoot_viewport_and_panel() -> None:
    _w, area, space, region = view3d()
    screen = _screen()
    ui = next(r for r in area.regions if r.type == "UI")
    view = _crop(screen, region)[HEADER_ROWS:, : region.width - ui.width]  # the view beside the sidebar
    _save_png(view, "blender_viewport_lit", scale=0.7)
    panel = _crop(screen, ui)
    _save_png(panel[: min(panel.shape[0], 600)], "blender_panel")


def _renders_grid() -> None:
    """EEVEE (top) and Cycles (bottom), default World (left) and baked probe (right), in one picture."""
    pics = os.path.join(OUT, "pictures")
    rows = [np.concatenate([_load_rgb(os.path.join(pics, f"{e}_{w}.png")) for w in ("unlit", "lit")], 1)
            for e in ("eevee", "cycles")]
    _save_png(np.concatenate(rows, 0), "blender_renders_lit_unlit")


def _open_tab(area, category: str = "GS-IBL") -> None:
    """Click the sidebar's GS-IBL tab (Region.active_panel_category is read-only in 5.2): simulated events, which
    Blender accepts only when started with --enable-event-simulate. The tabs run down the region's right edge."""
    ui = next(r for r in area.regions if r.type == "UI")
    try:
        ui.active_panel_category = category
        return
    except (AttributeError, TypeError):
        pass
    window = bpy.context.window_manager.windows[0]
    x, y = ui.x + ui.width - 12, ui.y + ui.height - TAB_FROM_TOP
    try:
        window.event_simulate(type="MOUSEMOVE", value="NOTHING", x=x, y=y)
        window.event_simulate(type="LEFTMOUSE", value="PRESS", x=x, y=y)
        window.event_simulate(type="LEFTMOUSE", value="RELEASE", x=x, y=y)
    except Exception as e:  # noqa: BLE001  without --enable-event-simulate: the picture shows another tab
        log(f"cannot open the {category} tab: {e}")


def pictures(pkg: str):
    """docs/img pictures: the viewport (Material Preview, Scene World on) with the splats around meshes lit by the
    baked probe, the sidebar panel after the bake, and EEVEE and Cycles renders with the default grey World
    (unlit) and with the baked one (lit). Written to DIR/pictures."""
    os.makedirs(os.path.join(OUT, "pictures"), exist_ok=True)
    yield 0.5, lambda: _picture_scene(pkg)
    yield 0.5, lambda: _unlit_world()
    yield 0.5, lambda: _render("EEVEE", "eevee_unlit")
    yield 0.5, lambda: _render("CYCLES", "cycles_unlit")
    yield 0.5, lambda: bpy.ops.gs_ibl.bake_probe()
    yield 0.5, lambda: _render("EEVEE", "eevee_lit")
    yield 0.5, lambda: _render("CYCLES", "cycles_lit")

    def viewport():
        _w, area, space, region = view3d()
        eye, target = Vector(VIEW_EYE), Vector(PICTURE_TARGET)
        r3d = space.region_3d
        r3d.view_rotation = (target - eye).to_track_quat("-Z", "Y")
        r3d.view_location, r3d.view_distance = target, (target - eye).length
        space.shading.type = "MATERIAL"
        space.shading.use_scene_world = True
        space.show_region_ui = True
        set_overlay(True, True)
        bpy.context.scene.camera.hide_set(True)
        for obj in bpy.context.view_layer.objects:
            obj.select_set(False)
        bpy.context.view_layer.objects.active = state["probe"]
        _open_tab(area)
    yield 0.5, viewport
    yield SETTLE * 3, _shoot_viewport_and_panel
    yield 0.5, _renders_grid


def finish(error: str | None = None) -> None:
    state["error"] = error
    write_result(os.path.join(OUT, "shots.json"), {
        "shots": state["shots"], "log": state["log"], "proxy": state.get("proxy"),
        "shader_check": state.get("shader_check"), "composite_check": state.get("composite_check"),
        "composite_real": state.get("composite_real"), "clicks": state.get("clicks"), "selects": state.get("selects"),
        "theme": state.get("theme"), "import": state.get("import"), "auto": state.get("auto"),
        "draw_log": state.get("draw_log"), "motion": state.get("motion")}, error)


start(steps, finish, SRC)
