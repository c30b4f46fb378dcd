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

and writes DIR/shots.json: per shot the 3D region's place on the screen, the view's matrices, the projected
centres of the test objects, the splat object's bounds corners and the overlay's own coverage image, which the
pytest driver uses to find the splat region. --pictures also writes the pictures for docs/img (panel, lit mesh,
EEVEE and Cycles renders lit and unlit). Failures are written to DIR/error.txt; Blender quits at the end.
"""
from __future__ import annotations

import importlib
import json
import math
import os
import subprocess
import sys
import time
import traceback

import bpy
import numpy as np
from mathutils import Matrix, Vector

ARGS = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def _arg(name: str, default=None):
    return ARGS[ARGS.index(name) + 1] if name in ARGS else default


OUT = os.path.abspath(_arg("--out", "/tmp/gui_overlay"))
SRC = _arg("--src")
ROOM = _arg("--room")
PICTURES = "--pictures" in ARGS
SETTLE = float(_arg("--settle", "6"))  # seconds the window gets to draw before a screenshot (llvmpipe is slow)
os.makedirs(OUT, exist_ok=True)

# The two views: eye, target. A looks into the room past the Occluder and at the Blob in front of the Backdrop;
# B looks at both from the side, across the floor (where the grid would show).
VIEWS = {"a": ((0.2, -2.1, 1.45), (0.35, 1.2, 0.75)), "b": ((-2.3, 1.6, 1.9), (0.7, -0.4, 0.6))}
OCCLUDER = (0.15, 0.75, 0.3)
BLOB, BACKDROP = (0.95, 0.1, 0.8), (1.15, 1.3, 0.8)
BLOB_RGB = (0.9, 0.08, 0.06)

state: dict = {"shots": {}, "log": []}


def log(msg: str) -> None:
    line = f"[gui_overlay {time.strftime('%H:%M:%S')}] {msg}"
    print(line, flush=True)
    state["log"].append(line)


def package():
    """The extension's package: the installed one (bl_ext.<repo>.gs_ibl) or the checkout's with --src."""
    if SRC:
        sys.path.insert(0, SRC)
        import gs_ibl_addon
        gs_ibl_addon.register()
        return "gs_ibl_addon"
    names = [m for m in bpy.context.preferences.addons.keys() if m.endswith("gs_ibl")]
    if not names:
        raise RuntimeError("the gs_ibl extension is not enabled in this Blender "
                           f"(enabled: {sorted(bpy.context.preferences.addons.keys())})")
    return names[0]


def mod(pkg: str, name: str):
    return importlib.import_module(f"{pkg}.{name}")


def view3d():
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                region = next(r for r in area.regions if r.type == "WINDOW")
                return window, area, area.spaces.active, region
    raise RuntimeError("no 3D Viewport in the window")


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
    splat_object, formats = mod(pkg, "blender.splat_object"), mod(pkg, "core.formats")
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
    log_ = [(t, s, ms) for t, sl, s, ms in mod(pkg, "blender.overlay").draw_log if sl == slot]
    state["motion"] = {"draws": log_, "last_nudge": state["last_nudge"],
                       "resolution": bpy.context.scene.gs_ibl_overlay.resolution_scale}
    log(f"motion: last nudge {state['last_nudge']:.2f}, draws {[(round(t, 2), s) for t, s, _ in log_[-8:]]}")


def record(shot: str, pkg: str) -> None:
    window, area, space, region = view3d()
    r3d = space.region_3d
    path = os.path.join(OUT, f"{shot}.png")
    subprocess.run(["import", "-window", "root", path], check=True)
    overlay = mod(pkg, "blender.overlay")
    room = state["room"]
    corners = [list(room.matrix_world @ Vector(c)) for c in room.bound_box]
    info = {"png": os.path.basename(path), "window": [window.width, window.height],
            "region": [region.x, region.y, region.width, region.height],
            "view_matrix": [list(r) for r in r3d.view_matrix], "window_matrix": [list(r) for r in r3d.window_matrix],
            "show_splats": bpy.context.scene.gs_ibl_overlay.show, "overlays": space.overlay.show_overlays,
            "points": {k: project(r3d, region, p) for k, p in
                       (("occluder", OCCLUDER), ("blob", BLOB), ("backdrop", BACKDROP))},
            "room_bounds": corners, "room_display": room.display_type,
            "last_draw": {str(k): v for k, v in overlay.last_draw.items()}, "error": overlay.last_error}
    if bpy.context.scene.gs_ibl_overlay.show:
        scale = bpy.context.scene.gs_ibl_overlay.resolution_scale
        img = overlay.splat_image(room, r3d, region.width, region.height, scale, slot="gui-check")
        cov = os.path.join(OUT, f"{shot}_coverage.npy")
        np.save(cov, img.rgba[..., 3])
        info["coverage"], info["coverage_rect"] = os.path.basename(cov), list(img.view.ndc_rect)
    state["shots"][shot] = info
    log(f"shot {shot}: {info['last_draw']} error={info['error']}")


def shader_check(pkg: str) -> None:
    """The overlay's shader against its numpy reference (overlay_math.to_display, window_depth): random colour,
    coverage and distances drawn into an offscreen buffer exactly as the draw handler draws, read back."""
    import gpu
    overlay, om = mod(pkg, "blender.overlay"), mod(pkg, "blender.overlay_math")
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
        colour_tex, depth_tex = overlay.textures(rgba, depth)
        overlay.draw_quads([(colour_tex, depth_tex, (-1.0, -1.0, 1.0, 1.0),
                             overlay.shader_params(view, exposure))])
        got = np.array(fb.read_color(0, 0, w, h, 4, 0, "FLOAT").to_list(), np.float32).reshape(h, w, 4)[::-1]
        got_depth = np.array(fb.read_depth(0, 0, w, h).to_list(), np.float32).reshape(h, w)[::-1]
    off.free()
    a = rgba[..., 3]
    want = np.where((a >= overlay.ALPHA_CUT)[..., None], om.to_display(rgba, exposure), 0.0)
    want_depth = np.where(a >= overlay.OPAQUE_CUT, om.window_depth(depth, view, om.DEPTH_PULL), 1.0)
    state["shader_check"] = {"colour_max_error": float(np.abs(got - want).max()),
                             "depth_max_error": float(np.abs(got_depth - want_depth).max()),
                             "pixels": w * h}
    log(f"shader check: {state['shader_check']}")


def steps(pkg: str):
    """The script: (seconds to wait before it, what to do), one after the other."""
    yield 1.0, lambda: shader_check(pkg)
    yield 1.0, lambda: build(pkg)
    for name in VIEWS:
        yield 1.0, lambda name=name: (set_view(name), set_overlay(False, True))
        yield SETTLE, lambda name=name: record(f"{name}_plain", pkg)
        yield 0.5, lambda: set_overlay(True, True)
        yield SETTLE * 2, lambda name=name: record(f"{name}_splats", pkg)
        yield 0.5, lambda: set_overlay(True, False)
        yield SETTLE, lambda name=name: record(f"{name}_clean", pkg)
    yield 0.5, lambda: set_overlay(True, True)
    # orbit a little (a view change every 0.3 s), then keep still: coarse frames while moving, then one timed
    # redraw at the full Resolution with no event at all
    for k in range(5):
        yield 0.3, lambda k=k: nudge(k)
    yield 2.5 + SETTLE, lambda: record_motion(pkg)
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
        bsdf = mod(pkg, "blender.compat").node_tree(mat).nodes.get("Principled BSDF")
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
    with open(os.path.join(OUT, "shots.json"), "w") as f:
        json.dump({"shots": state["shots"], "log": state["log"], "proxy": state.get("proxy"),
                   "shader_check": state.get("shader_check"),
                   "motion": state.get("motion"),
                   "blender": bpy.app.version_string, "python": sys.version.split()[0], "error": error}, f, indent=1)
    if error:
        with open(os.path.join(OUT, "error.txt"), "w") as f:
            f.write(error)
    bpy.ops.wm.quit_blender()


def main() -> None:
    bpy.context.preferences.view.show_splash = False  # a fresh user directory would open on the splash
    try:
        pkg = package()
    except Exception:  # noqa: BLE001
        finish(traceback.format_exc())
        return
    it = steps(pkg)
    pending = []

    busy = []

    def tick():
        # run the action that was waiting, then wait as long as the next one asks before running it
        if busy:  # a blocking render lets Blender run timers meanwhile: not this one again
            return 1.0
        if pending:
            busy.append(True)
            try:
                pending.pop()()
            except BaseException:  # noqa: BLE001  (a StopIteration inside an action is a failure too)
                finish(traceback.format_exc())
                return None
            finally:
                busy.clear()
        try:
            delay, action = next(it)
        except StopIteration:
            finish()
            return None
        except Exception:  # noqa: BLE001
            finish(traceback.format_exc())
            return None
        pending.append(action)
        return delay

    bpy.app.timers.register(tick, first_interval=1.0)


main()
