"""An artist's pass over the F12 features in the real Blender 5.2 GUI (the sid root; run through
test_matrix.run_gui_script like test_gui_render.py, see below): the sample room with a sphere resting on the floor
and Suzanne, Add Probe, Bake (Lighting Auto), a real F12 in Cycles then in EEVEE (frames saved), then Lighting Volume
over a sphere keyframed across the room, baked, and Render Animation (Ctrl F12; small frames, EEVEE). Screenshots of
the whole screen after each step (the sidebar's GS-IBL tab with Splats in Renders, the render window) for a person to
look at; DIR/artist.json holds the reports and timings. With ``--checks 1`` instead (240x135, EEVEE): F12 before any
bake (the "no shadows" message), the bake, the sidebar buttons' tooltips (the first one shows; Blender draws no second
tooltip without a real pointer move between), then F12 with Shadows on Splats on, off, and Transparent on and off
(RGBA frames c6..c9). With ``--world GUITAR.PLY``: the guitar capture before a blue World, F12 with Transparent off (the
World behind the splats) and on (RGBA frames w1, w2); add tests/data/guitar.compressed.ply to the inputs.

    blender --python gui_artist.py -- --out DIR --room ROOM.PLY

From the checkout (the zip built, installed in the sid root, Xvfb; everything lands in build/matrix/gui-artist/out,
the docs pictures blender_f12_room_*.png, blender_f12_window.png and blender_volume_animation.png come from there):

    .venv/bin/python -c "import sys, tempfile, pathlib; sys.path.insert(0, 'tests/real_blender');
    import test_matrix as t;
    t._INPUTS['zip'] = t.built_zip(); t.run_gui_script(t.Entry('gui-artist', 'sid', True, gui=True),
    pathlib.Path(tempfile.mkdtemp()), 'gui_artist.py', 'artist.json', '--room {inner}/room.ply',
    inputs=(t.REPO / 'samples' / 'room.ply',))"
"""
from __future__ import annotations

import math
import os
import subprocess
import time

import bpy
from mathutils import Vector

import sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import arg, focus, mod, start, view3d, write_result, xdo  # noqa: E402

OUT = os.path.abspath(arg("--out", "/tmp/gui_artist"))
ROOM = arg("--room")
SIZE = (480, 270)
ANIM_SIZE = (240, 135)
SAMPLES = 16  # EEVEE
CYCLES_SAMPLES = 128  # no denoiser in Debian's Blender
SPHERE = ((0.45, -0.55, 0.35), 0.35)  # resting on the floor below the lamp's side: its shadow on the splat floor
MONKEY = ((-0.2, -1.7, 0.27), 0.7)  # on the floor, left of the table
CAMERA = ((2.9, -0.5, 1.75), (-0.8, -0.2, 0.4), 72.0)
PATH = [(0.9, 0.7, 0.35), (0.1, 0.0, 0.35), (-1.2, 0.9, 0.35), (-2.4, 0.3, 0.35)]  # frames 1..4, to the red wall
os.makedirs(OUT, exist_ok=True)
state: dict = {"log": [], "steps": {}}


def log(msg: str) -> None:
    line = f"[gui_artist {time.strftime('%H:%M:%S')}] {msg}"
    print(line, flush=True)
    state["log"].append(line)


def shot(name: str) -> None:
    path = os.path.join(OUT, f"{name}.png")
    subprocess.run(["import", "-window", "root", path], check=True)
    log(f"screenshot {name}")


def _material(pkg: str, name: str, grey: float) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    bsdf = next(n for n in mod(pkg, "blender.common.compat").node_tree(mat).nodes
                if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (grey, grey, grey, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.5
    return mat


def build(pkg: str) -> None:
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    t0 = time.perf_counter()
    assert bpy.ops.gs_ibl.import_splats(filepath=ROOM, axis_preset="AUTO") == {"FINISHED"}
    state["import_s"] = time.perf_counter() - t0
    bpy.context.scene.gs_ibl_overlay.show = True
    (centre, radius), (m_at, m_size) = SPHERE, MONKEY
    bpy.ops.mesh.primitive_monkey_add(size=m_size, location=m_at, rotation=(0.0, 0.0, math.radians(105.0)))
    monkey = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    monkey.data.materials.append(_material(pkg, "Grey", 0.6))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=centre, segments=64, ring_count=32)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_material(pkg, "White", 0.8))
    state["sphere"] = sphere.name
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
    import addon_utils
    addon_utils.enable("cycles", default_set=True)
    r.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples = "CPU", CYCLES_SAMPLES
    scene.eevee.taa_render_samples = SAMPLES
    scene.view_settings.view_transform = "Standard"
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    sphere.select_set(True)
    bpy.context.view_layer.objects.active = sphere
    window, area, space, region = view3d()
    space.show_region_ui = True
    space.shading.type = "SOLID"
    for a in window.screen.areas:  # the Properties editor on the Render tab: Splats in Renders
        if a.type == "PROPERTIES":
            a.spaces.active.context = "RENDER"
    log(f"Blender {bpy.app.version_string}; import {state['import_s']:.1f} s")


def invoke(op: str, **kwargs) -> None:
    window, area, _space, region = view3d()
    with bpy.context.temp_override(window=window, area=area, region=region):
        result = getattr(bpy.ops.gs_ibl, op)("INVOKE_DEFAULT", **kwargs)
    state["steps"].setdefault(op, []).append(sorted(result))
    log(f"{op}: {sorted(result)}")


def wait_for_jobs(pkg: str, timeout: float = 400.0):
    jobs = mod(pkg, "blender.common.jobs")
    end = time.perf_counter() + timeout
    while jobs.running() and time.perf_counter() < end:
        yield 1.0, lambda: None


def probe():
    return next(o for o in bpy.data.objects if o.gs_ibl_probe.is_probe)


def bake_done(name: str) -> None:
    p = probe()
    s = p.gs_ibl_probe
    state["steps"][name] = {"report": s.last_report, "summary": s.last_summary, "lighting": s.lighting,
                            "parent": getattr(p.parent, "name", None), "location": list(p.matrix_world.translation),
                            "seconds": time.perf_counter() - state["t_bake"],
                            "world": getattr(bpy.context.scene.world, "name", None),
                            "objects": sorted(bpy.data.objects.keys())}
    log(f"{name}: {state['steps'][name]}")


def sidebar():
    _w, area, _s, _r = view3d()
    return next(r for r in area.regions if r.type == "UI")


def open_tab():
    for y in [240, *range(30, 600, 30)]:
        if sidebar().active_panel_category == "GS-IBL":
            break

        def click(y=y):
            window, _a, _s, _r = view3d()
            ui = sidebar()
            focus()
            xdo("mousemove", "--sync", ui.x + ui.width - 10, window.height - (ui.y + ui.height) + y)
            xdo("click", 1)
        yield 0.5, click
        yield 1.5, lambda: None


def pointer_away() -> None:
    window, _a, _s, _r = view3d()
    xdo("mousemove", "--sync", window.width // 3, window.height // 2)


def f12_keycode() -> str:
    r = subprocess.run(["xkbcomp", "-xkb", os.environ.get("DISPLAY", ":0"), "-"], capture_output=True, text=True)
    for line in r.stdout.splitlines():
        line = line.strip()
        if line.startswith("<FK12>") and "=" in line:
            return line.split("=", 1)[1].strip(" ;")
    return "96"


def press_f12(ctrl: bool = False) -> None:
    window, _a, _s, region = view3d()
    focus()
    xdo("mousemove", "--sync", region.x + region.width // 2, window.height - 1 - (region.y + region.height // 2))
    code = f12_keycode()
    if ctrl:
        xdo("keydown", "Control_L")
        xdo("key", code)
        xdo("keyup", "Control_L")
    else:
        xdo("key", code)
    state["t_f12"] = time.perf_counter()
    log(f"F12 pressed (ctrl {ctrl}, engine {bpy.context.scene.render.engine})")


def wait_for_render(timeout: float = 400.0):
    t0 = time.perf_counter()
    while not bpy.app.is_job_running("RENDER") and time.perf_counter() - t0 < 20.0:
        yield 0.25, lambda: None
    started = time.perf_counter() - t0
    while bpy.app.is_job_running("RENDER") and time.perf_counter() - t0 < timeout:
        yield 0.5, lambda: None
    state["last_render"] = {"started_s": started, "render_s": time.perf_counter() - t0}


def save_result(pkg: str, name: str) -> None:
    scene = bpy.context.scene
    result = bpy.data.images.get("Render Result")
    if result is not None and result.has_data:
        result.save_render(os.path.join(OUT, f"{name}.png"), scene=scene)
    record = mod(pkg, "blender.render.frame").last_render(scene)
    state["steps"][name] = {**state.get("last_render", {}), "engine": scene.render.engine,
                            "messages": record["messages"], "cancelled": record["cancelled"],
                            "frames": {str(k): v for k, v in record["frames"].items()},
                            "describe": mod(pkg, "blender.render.setup").describe(scene),
                            "film_transparent": scene.render.film_transparent,
                            "transparent": scene.gs_ibl_render.transparent,
                            "shadows": scene.gs_ibl_render.shadows}
    log(f"{name}: {state['steps'][name]}")
    shot(f"{name}_window")


def set_engine(engine: str) -> None:
    bpy.context.scene.render.engine = engine
    log(f"engine {engine}")


def close_render_windows() -> None:
    main = bpy.context.window_manager.windows[0]
    for w in list(bpy.context.window_manager.windows)[1:]:
        try:
            with bpy.context.temp_override(window=w):
                bpy.ops.wm.window_close()
        except Exception as e:  # noqa: BLE001
            log(f"window_close: {e}")
    log(f"windows now {len(bpy.context.window_manager.windows)} (main {main.width}x{main.height})")


def setup_volume() -> None:
    scene = bpy.context.scene
    sphere = bpy.data.objects[state["sphere"]]
    scene.frame_start, scene.frame_end = 1, len(PATH)
    for i, at in enumerate(PATH, 1):
        sphere.location = at
        sphere.keyframe_insert("location", frame=i)
    scene.frame_set(1)
    p = probe()
    p.gs_ibl_probe.lighting = "VOLUME"
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    p.select_set(True)
    bpy.context.view_layer.objects.active = p
    log(f"volume set: probe {p.name} parent {getattr(p.parent, 'name', None)}")


def setup_animation() -> None:
    scene = bpy.context.scene
    r = scene.render
    r.engine = "BLENDER_EEVEE"
    r.resolution_x, r.resolution_y = ANIM_SIZE
    r.filepath = os.path.join(OUT, "anim_")
    state["t_anim"] = time.perf_counter()


def anim_done(pkg: str) -> None:
    record = mod(pkg, "blender.render.frame").last_render(bpy.context.scene)
    state["steps"]["animation"] = {"seconds": time.perf_counter() - state["t_anim"],
                                   "files": sorted(f for f in os.listdir(OUT) if f.startswith("anim_")),
                                   "messages": record["messages"], "cancelled": record["cancelled"],
                                   "frames": {str(k): v for k, v in record["frames"].items()}}
    log(f"animation: {state['steps']['animation']}")
    shot("anim_window")


def steps(pkg: str):
    yield 1.0, lambda: build(pkg)
    yield 3.0, lambda: shot("01_built")
    yield 1.0, lambda: invoke("add_probe")
    yield 1.0, lambda: (state.__setitem__("t_bake", time.perf_counter()), invoke("bake_probe"))
    yield 3.0, lambda: shot("02_baking")
    yield from wait_for_jobs(pkg)
    yield 1.0, lambda: bake_done("bake_auto")
    yield from open_tab()
    yield 0.5, pointer_away
    yield 5.0, lambda: shot("03_baked_panel")
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 5.0, lambda: save_result(pkg, "f12_cycles")
    yield 1.0, lambda: set_engine("BLENDER_EEVEE")
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 5.0, lambda: save_result(pkg, "f12_eevee")
    yield 1.0, close_render_windows
    yield 1.0, setup_volume
    yield 3.0, lambda: shot("04_volume_set")
    yield 1.0, lambda: (state.__setitem__("t_bake", time.perf_counter()), invoke("bake_probe"))
    yield 5.0, lambda: shot("05_volume_baking")
    yield from wait_for_jobs(pkg)
    yield 1.0, lambda: bake_done("bake_volume")
    yield 0.5, pointer_away
    yield 5.0, lambda: shot("06_volume_baked")
    yield 0.5, setup_animation
    yield 0.5, lambda: press_f12(ctrl=True)
    yield from wait_for_render(600.0)
    yield 5.0, lambda: anim_done(pkg)


def set_render(**kw) -> None:
    for k, v in kw.items():
        setattr(bpy.context.scene.gs_ibl_render, k, v)
    log(f"render settings {kw}: film_transparent {bpy.context.scene.render.film_transparent}")


def hover(x: int, y: int, name: str):
    """The pointer over a button (screen pixels from the top left), its tooltip drawn, a screenshot."""
    yield 0.5, lambda: (focus(), xdo("mousemove", "--sync", x, y))
    yield 2.5, lambda: shot(name)
    yield 0.5, pointer_away


def save_rgba(pkg: str, name: str) -> None:
    scene = bpy.context.scene
    scene.render.image_settings.color_mode = "RGBA"
    save_result(pkg, name)
    scene.render.image_settings.color_mode = "RGB"


def check_steps(pkg: str):
    """The settings as a user tries them: F12 before any bake (no shadows: said?), Shadows on Splats off, Transparent
    on; the tooltips of the sidebar's squeezed buttons."""
    yield 1.0, lambda: build(pkg)
    yield 1.0, lambda: (setattr(bpy.context.scene.render, "engine", "BLENDER_EEVEE"),
                        setattr(bpy.context.scene.render, "resolution_percentage", 50))
    yield from open_tab()
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_result(pkg, "c1_unbaked")
    yield 1.0, lambda: invoke("add_probe")
    yield 1.0, lambda: (state.__setitem__("t_bake", time.perf_counter()), invoke("bake_probe"))
    yield from wait_for_jobs(pkg)
    yield 1.0, lambda: bake_done("bake_auto")
    yield 3.0, lambda: shot("c2_baked")
    yield from hover(1100, 226, "c3_tip_shadows")
    yield from hover(1238, 205, "c4_tip_transparent")
    yield from hover(1080, 205, "c5_tip_splats_in_renders")
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_result(pkg, "c6_shadows_on")
    yield 0.5, lambda: set_render(shadows=False)
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_result(pkg, "c7_shadows_off")
    yield 0.5, lambda: set_render(shadows=True, transparent=True)
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_rgba(pkg, "c8_transparent")
    yield 0.5, lambda: set_render(transparent=False)
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_rgba(pkg, "c9_opaque")


def build_world(pkg: str) -> None:
    """The guitar capture (nothing around it) before a blue World and a grey sphere: the World must show behind the
    splats unless Transparent is on."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    assert bpy.ops.gs_ibl.import_splats(filepath=arg("--world"), axis_preset="OPENCV") == {"FINISHED"}
    scene = bpy.context.scene
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.use_nodes = True
    bg = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    bg.inputs["Color"].default_value = (0.1, 0.25, 0.8, 1.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.42, location=(0.95, 1.45, 0.42))
    bpy.ops.object.shade_smooth()
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.sensor_fit, cam.data.angle = "HORIZONTAL", math.radians(58.0)
    scene.collection.objects.link(cam)
    cam.location = (2.2, 7.6, 2.0)
    cam.rotation_euler = (Vector((0.15, 0.0, 1.85)) - cam.location).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = *ANIM_SIZE, 100
    r.engine = "BLENDER_EEVEE"
    scene.eevee.taa_render_samples = SAMPLES
    scene.view_settings.view_transform = "Standard"
    scene.gs_ibl_render.shadows = False  # no probe here
    log(f"world scene: film_transparent {r.film_transparent}, transparent {scene.gs_ibl_render.transparent}")


def world_steps(pkg: str):
    yield 1.0, lambda: build_world(pkg)
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_rgba(pkg, "w1_world")
    yield 0.5, lambda: set_render(transparent=True)
    yield 0.5, press_f12
    yield from wait_for_render()
    yield 3.0, lambda: save_rgba(pkg, "w2_transparent")
    yield 0.5, lambda: set_render(enabled=False)
    yield 1.0, lambda: log(f"Splats in Renders off: film_transparent {bpy.context.scene.render.film_transparent}")


def finish(error: str | None = None) -> None:
    write_result(os.path.join(OUT, "artist.json"), {"steps": state["steps"], "log": state["log"]}, error)


start(world_steps if arg("--world") else check_steps if arg("--checks") else steps, finish)
