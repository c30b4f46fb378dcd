"""Run by a real Blender with its GUI (tests/real_blender/test_gui_jobs.py): long work beside the UI (issue 23).

    blender --python gui_jobs.py -- --out DIR --room ROOM.PLY --big BIG.PLY [--src CHECKOUT]

The sample room is imported (by a script: at once) and a probe added with 1024^2 faces, a bake of ~10-20 s on
llvmpipe. Then, with steps scheduled by bpy.app.timers so the window draws between them:

  bake_running   the Bake operator invoked as the panel's button does (INVOKE_DEFAULT): a screenshot of the window
                 while it runs (the status bar holds the job's line), the job's status lines
  escape         a real Esc key through xdotool (the window focused)
  after_cancel   the job has ended, cancelled: the scene's World, the images and the probe's report as before
  bake_done      the same bake invoked again at face size 0 (auto) and left to finish: the World is the probe's
  import_*       BIG.PLY imported through the path the file browser takes (execute after invoke: from_ui), with
                 Show Splats on: the read on a worker, the object made on the main thread, then the overlay's first
                 upload as a background job; screenshots while it reads and once drawn
  drop_*         ROOM.PLY as a dropped file: invoke with the path opens the options popup, a real Return key
                 confirms it, and the import runs as a modal job

A heartbeat timer (every 50 ms) records when the main thread ran it: the gaps between its calls are how long
Blender's event loop was blocked (a frozen UI shows as a gap as long as the freeze). DIR/jobs.json holds what each
step saw; failures go to DIR/error.txt; Blender quits at the end.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import arg, focus, mod, start, view3d, write_result, xdo  # noqa: E402

OUT = os.path.abspath(arg("--out", "/tmp/gui_jobs"))
SRC = arg("--src")
ROOM = arg("--room")
BIG = arg("--big")
PROBE = (0.0, 0.45, 0.9)
os.makedirs(OUT, exist_ok=True)
state: dict = {"log": [], "beats": [], "steps": {}}


def log(msg: str) -> None:
    line = f"[gui_jobs {time.strftime('%H:%M:%S')}] {msg}"
    print(line, flush=True)
    state["log"].append(line)


def heartbeat() -> float:
    state["beats"].append(time.perf_counter())
    return 0.05


def gaps_since(t0: float) -> list[float]:
    beats = [t for t in state["beats"] if t >= t0]
    return [b - a for a, b in zip(beats, beats[1:])]


def longest_gaps(pkg: str, t0: float, n: int = 4) -> list[dict]:
    """The ``n`` longest gaps since ``t0`` (seconds after t0), with the overlay draws that ended inside each (their
    draw ms): what held the main thread."""
    beats = [t for t in state["beats"] if t >= t0]
    draws = list(mod(pkg, "blender.viewport.overlay").draw_log)  # (time.monotonic(), region, scale, render ms, draw ms)
    shift = time.perf_counter() - time.monotonic()
    gaps = sorted(zip(beats, beats[1:]), key=lambda ab: ab[0] - ab[1])[:n]
    return [{"at": round(a - t0, 2), "gap": round(b - a, 3),
             "draws": [(round(d[3]), round(d[4])) for d in draws if a <= d[0] + shift <= b]} for a, b in gaps]


def screenshot(name: str) -> str:
    path = os.path.join(OUT, f"{name}.png")
    subprocess.run(["import", "-window", "root", path], check=True)
    return os.path.basename(path)


def build(pkg: str) -> None:
    for obj in list(bpy.data.objects):  # the startup file's cube, camera and light
        bpy.data.objects.remove(obj)
    assert bpy.ops.gs_ibl.import_splats(filepath=ROOM, axis_preset="AUTO") == {"FINISHED"}
    room = bpy.context.active_object
    state["room"] = room.name
    bpy.context.scene.cursor.location = PROBE
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    s = probe.gs_ibl_probe
    s.splats, s.face_size, s.irradiance_size = room, 1024, 16
    s.lighting = "WORLD"  # the World probe alone: no per-mesh probes to bake on llvmpipe
    state["probe"] = probe.name
    scene = bpy.context.scene
    state["before"] = {"world": scene.world.name if scene.world else None, "images": sorted(bpy.data.images.keys()),
                       "report": s.last_report}
    bpy.app.timers.register(heartbeat, first_interval=0.05)
    log(f"built: {state['before']}")


def invoke(op: str, **kwargs) -> None:
    """Call an operator as a button of the 3D View's window does (INVOKE_DEFAULT, with that window's context)."""
    window, area, _space, region = view3d()
    with bpy.context.temp_override(window=window, area=area, region=region):
        result = getattr(bpy.ops.gs_ibl, op)("INVOKE_DEFAULT", **kwargs)
    state["steps"][f"invoke_{op}_{len(state['steps'])}"] = sorted(result)
    log(f"{op}: {sorted(result)}")


def look(pkg: str, name: str) -> None:
    """What a user sees now: a screenshot, and the running jobs' status lines (the status bar's text)."""
    jobs = mod(pkg, "blender.common.jobs")
    running = jobs.running()
    state["steps"][name] = {"png": screenshot(name), "status": [r.status() for r in running],
                            "fractions": [r.fraction for r in running], "time": time.perf_counter()}
    log(f"{name}: {state['steps'][name]['status']}")


def start_bake(pkg: str, face_size: int) -> None:
    probe = bpy.data.objects[state["probe"]]
    probe.gs_ibl_probe.face_size = face_size
    state["t_bake"] = time.perf_counter()
    invoke("bake_probe")


def escape() -> None:
    focus()
    window, _a, _s, region = view3d()
    # the pointer over the 3D View, where a user's Esc lands
    xdo("mousemove", "--sync", region.x + region.width // 2, window.height - 1 - (region.y + region.height // 2))
    xdo("key", "Escape")
    state["t_escape"] = time.perf_counter()


def wait_for_jobs(pkg: str, name: str, timeout: float = 240.0):
    """Steps that wait (a second at a time) until no job runs, then record ``name``."""
    jobs = mod(pkg, "blender.common.jobs")
    end = time.perf_counter() + timeout
    while jobs.running() and time.perf_counter() < end:
        yield 1.0, lambda: None
    yield 0.5, lambda: record_end(pkg, name)


def record_end(pkg: str, name: str) -> None:
    jobs = mod(pkg, "blender.common.jobs")
    scene = bpy.context.scene
    probe = bpy.data.objects.get(state["probe"])
    s = probe.gs_ibl_probe if probe is not None else None
    since = state.get("t_bake", 0.0)
    gaps = gaps_since(since)
    state["steps"][name] = {
        "running": [r.status() for r in jobs.running()], "world": scene.world.name if scene.world else None,
        "probe_world": s.world.name if s is not None and s.world is not None else None,
        "images": sorted(bpy.data.images.keys()), "report": s.last_report if s is not None else None,
        "seconds": time.perf_counter() - since, "max_gap": max(gaps, default=0.0), "beats": len(gaps),
        "gaps_over_0.2": sum(g > 0.2 for g in gaps), "gaps_over_0.5": sum(g > 0.5 for g in gaps),
        "escape_to_end": (time.perf_counter() - state["t_escape"]) if "t_escape" in state else None,
        "longest": longest_gaps(pkg, since), "load": os.getloadavg()[0],
        "png": screenshot(name)}
    log(f"{name}: {state['steps'][name]}")


def import_big(pkg: str) -> None:
    bpy.context.scene.gs_ibl_overlay.show = False
    state["objects_before_import"] = sorted(o.name for o in bpy.data.objects)
    state["t_bake"] = time.perf_counter()
    window, area, _space, region = view3d()
    with bpy.context.temp_override(window=window, area=area, region=region):
        # what the file browser's Import button does: execute() of an operator its invoke() opened
        result = bpy.ops.gs_ibl.import_splats("EXEC_DEFAULT", filepath=BIG, axis_preset="BLENDER", from_ui=True)
    state["steps"]["import_call"] = sorted(result)
    log(f"import: {sorted(result)}")


def import_record(pkg: str) -> None:
    overlay = mod(pkg, "blender.viewport.overlay")
    _w, _a, _s, region = view3d()
    new = sorted(set(o.name for o in bpy.data.objects) - set(state["objects_before_import"]))
    record_end(pkg, "import_done")
    state["steps"]["import_done"].update(new=new, show=bpy.context.scene.gs_ibl_overlay.show,
                                         drawn=overlay.last_draw.get(region.as_pointer(), {}).get("objects_drawn"),
                                         overlay_error=overlay.error_text())


def drop_import(pkg: str) -> None:
    """What a file dropped on the viewport does: invoke with the path known opens the options popup."""
    state["objects_before_drop"] = sorted(o.name for o in bpy.data.objects)
    invoke("import_splats", filepath=ROOM)


def confirm() -> None:
    focus()
    xdo("key", "Return")  # the popup's OK: execute(), which from a window runs the import as a modal job


def drop_record(pkg: str) -> None:
    new = sorted(set(o.name for o in bpy.data.objects) - set(state["objects_before_drop"]))
    state["steps"]["drop_done"] = {"new": new, "png": screenshot("drop_done"),
                                   "running": [r.status() for r in mod(pkg, "blender.common.jobs").running()]}
    log(f"drop: {state['steps']['drop_done']}")


def steps(pkg: str):
    yield 1.0, lambda: build(pkg)
    yield 3.0, lambda: start_bake(pkg, 1024)
    yield 4.0, lambda: look(pkg, "bake_running")
    yield 2.0, lambda: look(pkg, "bake_running_2")
    yield 0.5, escape
    yield 0.3, lambda: look(pkg, "cancelling")
    yield from wait_for_jobs(pkg, "after_cancel")
    yield 1.0, lambda: start_bake(pkg, 0)
    yield 1.5, lambda: look(pkg, "bake_auto_running")
    yield from wait_for_jobs(pkg, "bake_done")
    yield 1.0, lambda: import_big(pkg)
    yield 1.0, lambda: look(pkg, "import_running")
    yield from wait_for_jobs(pkg, "import_read")
    yield 0.5, lambda: setattr(bpy.context.scene.gs_ibl_overlay, "show", True)
    yield 1.0, lambda: look(pkg, "upload_running")
    yield from wait_for_jobs(pkg, "upload_done")
    yield 8.0, lambda: import_record(pkg)
    yield 0.5, lambda: drop_import(pkg)
    yield 2.0, lambda: look(pkg, "drop_popup")
    yield 0.5, confirm
    yield from wait_for_jobs(pkg, "drop_jobs")
    yield 1.0, lambda: drop_record(pkg)


def finish(error: str | None = None) -> None:
    write_result(os.path.join(OUT, "jobs.json"), {"steps": state["steps"], "before": state.get("before"),
                                                  "log": state["log"]}, error)


start(steps, finish, SRC)
