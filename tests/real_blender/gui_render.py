"""Run by a real Blender with its GUI (tests/real_blender/test_gui_render.py): the panel after a bake, then an F12
frame with the splats in it, as a user gets them (issues 35 and 36).

    blender --python gui_render.py -- --out DIR --room ROOM.PLY [--src CHECKOUT] [--engine EEVEE|CYCLES]

The sample room is imported (by a script: at once) with Show Splats on; a white sphere and a grey Suzanne are put on
its open floor, the sphere behind the room's blue splat ball (seen from the camera, the ball hides part of it), and
a camera looks at them from the room's +X side. Then, with steps scheduled by bpy.app.timers so the window draws
between them:

  add_probe    Add GS-IBL Probe as the panel's button calls it (INVOKE_DEFAULT), the sphere selected: the probe at it
  bake         Bake / Refresh invoked as the panel's button does (a modal job), waited for
  panel        the sidebar opened, its GS-IBL tab clicked with xdotool (a real click), a screenshot: panel.png
  f12          a real F12 key (xdotool, the pointer over the 3D View): Render Image opens the render window and
               renders (Cycles on the CPU, 16 spp, 480x270) as a job; waited for, then a screenshot with the frame in
               the render window (f12_window.png) and the Render Result saved as f12_result.png

DIR/render.json holds what each step saw: the sidebar's place on the screen, the X windows' geometry (xdotool), the
render handler's record of the frame (splats drawn, messages) and where the test objects fall in the frame (for
the checks in test_gui_render.py). Failures go to DIR/error.txt; Blender quits at the end.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import bpy
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import arg, focus, mod, start, view3d, write_result, xdo  # noqa: E402

OUT = os.path.abspath(arg("--out", "/tmp/gui_render"))
SRC = arg("--src")
ROOM = arg("--room")
SETTLE = float(arg("--settle", "5"))  # seconds the window gets to draw before a screenshot (llvmpipe is slow)
SIZE = (480, 270)
SAMPLES = 16
ENGINE = arg("--engine", "EEVEE").upper()  # or CYCLES (on the CPU)
# The room's picture in scripts/f12_pictures.py, with Suzanne on the open floor instead of on the table.
SPHERE = ((0.55, -1.3, 0.35), 0.35)
MONKEY = ((-0.2, 0.25, 0.4), 0.7)
CAMERA = ((2.9, -0.5, 1.75), (-0.8, -0.7, 0.6), 72.0)  # position, look-at, horizontal field of view (degrees)
# splat objects of samples/room.ply (core.synthetic.sample_environment): the blue ball on the floor (in front of the
# sphere), the red -X wall (behind Suzanne)
BLUE_BALL = ((1.2, -1.5, 0.4), 0.4)
RED_WALL = (-3.0, 0.6, 1.8)
TAB_FROM_TOP = 240  # where the GS-IBL tab (Item, Tool, View, Animation, GS-IBL) is first looked for
os.makedirs(OUT, exist_ok=True)
state: dict = {"log": [], "steps": {}}


def log(msg: str) -> None:
    line = f"[gui_render {time.strftime('%H:%M:%S')}] {msg}"
    print(line, flush=True)
    state["log"].append(line)


def screenshot(name: str) -> str:
    path = os.path.join(OUT, f"{name}.png")
    subprocess.run(["import", "-window", "root", path], check=True)
    return os.path.basename(path)


def x_windows() -> list[dict]:
    """Every X window named like Blender's (the main one, the render window): title and geometry on the screen."""
    r = subprocess.run(["xdotool", "search", "--name", "Blender"], capture_output=True, text=True)
    out = []
    for wid in r.stdout.split():
        name = subprocess.run(["xdotool", "getwindowname", wid], capture_output=True, text=True).stdout.strip()
        geo = subprocess.run(["xdotool", "getwindowgeometry", "--shell", wid], capture_output=True, text=True).stdout
        g = dict(line.split("=", 1) for line in geo.split() if "=" in line)
        out.append({"id": wid, "name": name, **{k.lower(): int(g[k]) for k in ("X", "Y", "WIDTH", "HEIGHT") if k in g}})
    return out


def blender_windows() -> list[dict]:
    return [{"x": w.x, "y": w.y, "width": w.width, "height": w.height,
             "areas": [{"type": a.type, "x": a.x, "y": a.y, "width": a.width, "height": a.height}
                       for a in w.screen.areas]} for w in bpy.context.window_manager.windows]


def _material(pkg: str, name: str, grey: float) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    bsdf = next(n for n in mod(pkg, "blender.common.compat").node_tree(mat).nodes
                if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (grey, grey, grey, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.5
    return mat


def build(pkg: str) -> None:
    for obj in list(bpy.data.objects):  # the startup file's cube, camera and light
        bpy.data.objects.remove(obj)
    assert bpy.ops.gs_ibl.import_splats(filepath=ROOM, axis_preset="AUTO") == {"FINISHED"}
    room = bpy.context.active_object
    state["room"] = room.name
    bpy.context.scene.gs_ibl_overlay.show = True
    (centre, radius), (m_at, m_size) = SPHERE, MONKEY
    bpy.ops.mesh.primitive_monkey_add(size=m_size, location=m_at, rotation=(0.0, 0.0, math.radians(76.0)))
    monkey = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    monkey.data.materials.append(_material(pkg, "Grey", 0.6))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=centre, segments=64, ring_count=32)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_material(pkg, "White", 0.8))
    state["meshes"] = [sphere.name, monkey.name]
    position, look_at, fov = CAMERA
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.sensor_fit, cam.data.angle = "HORIZONTAL", math.radians(fov)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = position
    cam.rotation_euler = (Vector(look_at) - Vector(position)).to_track_quat("-Z", "Y").to_euler()
    scene = bpy.context.scene
    scene.camera = cam
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = *SIZE, 100
    r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGB"
    if ENGINE == "CYCLES":  # grainy at 16 samples: Debian's Blender has no denoiser
        import addon_utils
        addon_utils.enable("cycles", default_set=True)  # a fresh user directory may lack it
        r.engine = "CYCLES"
        scene.cycles.device, scene.cycles.samples = "CPU", SAMPLES
    else:
        r.engine = "BLENDER_EEVEE"
        scene.eevee.taa_render_samples = SAMPLES
    scene.view_settings.view_transform = "Standard"  # the capture's colours as captured
    # the sphere selected, as a user leaves it before Add Probe: the probe goes to it
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    sphere.select_set(True)
    bpy.context.view_layer.objects.active = sphere
    window, area, space, region = view3d()
    space.show_region_ui = True  # the sidebar (N)
    space.shading.type = "SOLID"
    log(f"Blender {bpy.app.version_string}, window {window.width}x{window.height}; "
        f"built: {sorted(bpy.data.objects.keys())}")


def invoke(op: str, **kwargs) -> None:
    """Call an operator as a button of the 3D View's window does (INVOKE_DEFAULT, with that window's context)."""
    window, area, _space, region = view3d()
    with bpy.context.temp_override(window=window, area=area, region=region):
        result = getattr(bpy.ops.gs_ibl, op)("INVOKE_DEFAULT", **kwargs)
    state["steps"][op] = sorted(result)
    log(f"{op}: {sorted(result)}")


def wait_for_jobs(pkg: str, timeout: float = 300.0):
    jobs = mod(pkg, "blender.common.jobs")
    end = time.perf_counter() + timeout
    while jobs.running() and time.perf_counter() < end:
        yield 1.0, lambda: None


def bake_done(pkg: str) -> None:
    probe = next(o for o in bpy.data.objects if o.gs_ibl_probe.is_probe)
    s = probe.gs_ibl_probe
    state["probe"] = probe.name
    state["steps"]["bake"] = {"report": s.last_report, "summary": s.last_summary,
                              "world": bpy.context.scene.world.name if bpy.context.scene.world else None,
                              "probe_world": s.world.name if s.world else None,
                              "parent": getattr(probe.parent, "name", None),
                              "seconds": time.perf_counter() - state["t_bake"]}
    log(f"bake: {state['steps']['bake']}")


def sidebar():
    _w, area, _s, _r = view3d()
    return next(r for r in area.regions if r.type == "UI")


def click_tab(y_from_top: int) -> None:
    """A real click on the sidebar's tab column (its right edge) ``y_from_top`` pixels below the region's top."""
    window, _a, _s, _r = view3d()
    ui = sidebar()
    focus()
    xdo("mousemove", "--sync", ui.x + ui.width - 10, window.height - (ui.y + ui.height) + y_from_top)
    xdo("click", 1)
    state.setdefault("tab_clicks", []).append(y_from_top)


def open_tab():
    """Click the GS-IBL tab; where the tabs are depends on the theme and the add-ons: look down the column until
    the sidebar shows it."""
    for y in [TAB_FROM_TOP, *range(30, 600, 30)]:
        if sidebar().active_panel_category == "GS-IBL":
            break
        yield 0.5, lambda y=y: click_tab(y)
        yield 1.5, lambda: None  # the click handled and drawn before the next look
    yield 0.5, lambda: state["steps"].__setitem__("tab", sidebar().active_panel_category)


def shoot_panel() -> None:
    window, _a, _s, _r = view3d()
    ui = sidebar()
    # the pointer off the panel (a hovered button is drawn lighter)
    xdo("mousemove", "--sync", window.width // 3, window.height // 2)
    state["steps"]["panel"] = {"png": screenshot("panel"), "tab": ui.active_panel_category,
                               "region": [ui.x, ui.y, ui.width, ui.height], "window": [window.width, window.height]}
    log(f"panel: {state['steps']['panel']}")


def f12_keycode() -> str:
    """F12's X keycode. `xdotool key F12` sends Alt+F12 under Xvfb's keymap (xdotool picks a level of the key that
    needs Mod1), which Blender does not take for Render Image; the bare keycode is a plain F12."""
    r = subprocess.run(["xkbcomp", "-xkb", os.environ.get("DISPLAY", ":0"), "-"], capture_output=True, text=True)
    for line in r.stdout.splitlines():
        line = line.strip()
        if line.startswith("<FK12>") and "=" in line:
            return line.split("=", 1)[1].strip(" ;")
    return "96"  # evdev's


def press_f12() -> None:
    window, _a, _s, region = view3d()
    focus()
    # the pointer over the 3D View, where a user presses F12 (Render > Render Image)
    xdo("mousemove", "--sync", region.x + region.width // 2, window.height - 1 - (region.y + region.height // 2))
    state["t_f12"] = time.perf_counter()
    state["windows_before"] = len(bpy.context.window_manager.windows)
    code = f12_keycode()
    xdo("key", code)
    log(f"F12 pressed (keycode {code})")


def wait_for_render(timeout: float = 300.0):
    t0 = time.perf_counter()
    while not bpy.app.is_job_running("RENDER") and time.perf_counter() - t0 < 20.0:
        yield 0.25, lambda: None
        log(f"waiting: {len(bpy.context.window_manager.windows)} windows, running {bpy.app.is_job_running('RENDER')}, "
            f"{[x['name'] for x in x_windows()]}")
    state["render_started_s"] = time.perf_counter() - t0
    while bpy.app.is_job_running("RENDER") and time.perf_counter() - t0 < timeout:
        yield 0.5, lambda: None
    state["render_s"] = time.perf_counter() - t0


def project(scene, point) -> list[float]:
    """A world point -> (column, row from the top, depth) in the rendered frame."""
    from bpy_extras.object_utils import world_to_camera_view
    v = world_to_camera_view(scene, scene.camera, Vector(point))
    return [v.x * SIZE[0], (1.0 - v.y) * SIZE[1], v.z]


def disc(scene, centre, radius: float) -> dict:
    """A ball's outline in the frame: its projected centre and (about) its radius in pixels."""
    cam = scene.camera
    right = cam.matrix_world.to_3x3() @ Vector((1.0, 0.0, 0.0))
    c = project(scene, centre)
    e = project(scene, Vector(centre) + right * radius)
    return {"centre": c[:2], "radius": math.hypot(e[0] - c[0], e[1] - c[1]), "depth": c[2]}


def shoot_render(pkg: str) -> None:
    scene = bpy.context.scene
    frame = mod(pkg, "blender.render.frame")
    result = bpy.data.images.get("Render Result")
    saved = None
    if result is not None and result.has_data:
        saved = os.path.join(OUT, "f12_result.png")
        result.save_render(saved, scene=scene)
    record = frame.last_render(scene)
    monkey_at, _size = MONKEY
    state["steps"]["f12"] = {
        "png": screenshot("f12_window"), "result": os.path.basename(saved) if saved else None,
        "render_started_s": state.get("render_started_s"), "render_s": state.get("render_s"),
        "windows_before": state.get("windows_before"), "windows": blender_windows(), "x_windows": x_windows(),
        "record": {"messages": record["messages"], "cancelled": record["cancelled"],
                   "frames": {str(k): v for k, v in record["frames"].items()}},
        "size": list(SIZE), "engine": scene.render.engine, "samples": SAMPLES,
        "describe": mod(pkg, "blender.render.setup").describe(scene)[0],
        "sphere": disc(scene, *SPHERE), "blue_ball": disc(scene, *BLUE_BALL),
        "monkey": project(scene, monkey_at)[:2], "red_wall": project(scene, RED_WALL)[:2]}
    log(f"f12: {state['steps']['f12']}")


def steps(pkg: str):
    yield 1.0, lambda: build(pkg)
    yield 2.0, lambda: invoke("add_probe")
    yield 1.0, lambda: (state.__setitem__("t_bake", time.perf_counter()), invoke("bake_probe"))
    yield from wait_for_jobs(pkg)
    yield 1.0, lambda: bake_done(pkg)
    yield from open_tab()
    yield SETTLE, shoot_panel
    yield 0.5, press_f12
    yield from wait_for_render()
    yield SETTLE, lambda: shoot_render(pkg)


def finish(error: str | None = None) -> None:
    write_result(os.path.join(OUT, "render.json"), {"steps": state["steps"], "meshes": state.get("meshes"),
                                                    "tab_clicks": state.get("tab_clicks"), "log": state["log"]}, error)


start(steps, finish, SRC)
