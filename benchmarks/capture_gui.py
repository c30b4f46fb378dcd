"""Run by a real Blender with its GUI (benchmarks/capture_bench.py, sid root, Xvfb): one capture-sized PLY through
the stages a user goes through, timed, with a heartbeat timer measuring how long the main thread was away.

    blender --python capture_gui.py -- --out DIR --ply FILE.PLY [--stage-limit 300] [--orbit-s 8]

Stages (each waits for the last to end; the window draws in between, driven by gui_common.run_steps):

  import   the import operator as the file browser's Import button calls it (EXEC_DEFAULT, from_ui=True where the
           extension has that property: the job runs beside the UI; plain EXEC in older versions), Show Splats off;
           ends when the object exists and no job runs
  show     Show Splats turned on: ends with the end of the overlay's first draw that rendered splats (draw_log's
           render ms > 0: the first upload included)
  orbit    the view turned 2 degrees every 0.1 s (the area redrawn after each) for --orbit-s seconds, longer until
           3 frames were drawn (at most --stage-limit): the overlay's frames per second and per-frame draw time
           (overlay.draw_log) at the window's region size
  bake     a probe at the scene's centre, face size 0 (auto), Lighting World Probe, the panel's Bake button
           (INVOKE_DEFAULT with the 3D View's window, area and region); ends when no job runs and the report is new
  rebake   the probe moved 0.25 m, the same button again
  rebake_hidden  Show Splats off, the probe moved back, the button again (what the overlay's redraws cost a bake)

Per stage: wall seconds, the longest gap between heartbeats (the heartbeat asks for 50 ms: a gap is how long the
event loop was blocked) and how many gaps were longer than 0.2 s, the load average. DIR/capture.json holds it all;
Blender quits at the end. A stage that does not end within --stage-limit is recorded as a timeout and ends the run.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import arg, mod, start, view3d, write_result  # noqa: E402

OUT = os.path.abspath(arg("--out", "/tmp/capture_gui"))
PLY = arg("--ply")
STAGE_LIMIT_S = float(arg("--stage-limit", 300))
ORBIT_S = float(arg("--orbit-s", 8))
PROBE = (0.0, 0.0, 0.0)
os.makedirs(OUT, exist_ok=True)
state: dict = {"log": [], "beats": [], "cpu": [], "stages": {}, "draws": []}
now = time.monotonic  # the overlay's draw_log is in time.monotonic too


def log(msg: str) -> None:
    line = f"[capture_gui {time.strftime('%H:%M:%S')}] {msg}"
    print(line, flush=True)
    state["log"].append(line)


def heartbeat() -> float:
    state["beats"].append(now())
    state["cpu"].append((state["beats"][-1], time.thread_time(), time.process_time()))  # main thread, process
    return 0.05


def cpu_between(t0: float, t1: float) -> dict:
    """CPU seconds over [t0, t1] (from the beats around it): the main thread's own (busy, e.g. drawing, or idle,
    e.g. waiting for the GIL or the event loop asleep) and the whole process's (workers, Mesa's threads)."""
    before = [c for c in state["cpu"] if c[0] <= t0][-1:]
    after = [c for c in state["cpu"] if c[0] >= t1][:1]
    if not before or not after:
        return {}
    (a, ta, pa), (b, tb, pb) = before[0], after[0]
    return {"cpu_wall_s": b - a, "main_thread_cpu_s": tb - ta, "process_cpu_s": pb - pa}


def gaps(t0: float, t1: float) -> list[float]:
    """Gaps between heartbeats over [t0, t1], from the last beat before t0 to the first after t1: a block that
    began with the stage's own call (a blocking operator) counts in full."""
    beats = state["beats"]
    before = [b for b in beats if b <= t0]
    after = [b for b in beats if b >= t1]
    inside = [b for b in beats if t0 < b < t1]
    seq = before[-1:] + inside + after[:1]
    return [b - a for a, b in zip(seq, seq[1:])]


def jobs_running(pkg: str) -> list:
    try:
        jobs = mod(pkg, "blender.common.jobs")
    except ImportError:  # before the jobs work: everything ran inside the operator's call
        return []
    return jobs.running()


def collect_draws(pkg: str) -> None:
    """Copy the overlay's draw_log (a deque of 64) into our own list before it wraps."""
    _w, _a, _s, region = view3d()
    slot = region.as_pointer()
    last = state["draws"][-1][0] if state["draws"] else -1.0
    for t, sl, scale, ms, dms in list(mod(pkg, "blender.viewport.overlay").draw_log):
        if sl == slot and t > last:
            state["draws"].append((t, scale, ms, dms))


def redraw() -> None:
    view3d()[1].tag_redraw()


# ------------------------------------------------------------------------------------------------------- stages

def setup(pkg: str) -> None:
    for obj in list(bpy.data.objects):  # the startup file's cube, camera and light
        bpy.data.objects.remove(obj)
    bpy.context.scene.gs_ibl_overlay.show = False
    window, _area, space, region = view3d()
    r3d = space.region_3d
    from mathutils import Vector
    eye, target = Vector((9.0, -9.0, 6.0)), Vector((0.0, 0.0, 0.0))  # the whole 10 m box in view
    d = target - eye
    r3d.view_perspective = "PERSP"
    r3d.view_rotation = d.to_track_quat("-Z", "Y")
    r3d.view_location = target
    r3d.view_distance = d.length
    state["info"] = {"blender": bpy.app.version_string, "python": sys.version.split()[0],
                     "window": [window.width, window.height], "region": [region.width, region.height],
                     "resolution_scale": bpy.context.scene.gs_ibl_overlay.resolution_scale,
                     "has_jobs": _has_jobs(pkg), "ply": PLY, "ply_bytes": os.path.getsize(PLY)}
    bpy.app.timers.register(heartbeat, first_interval=0.05)
    # every redraw of the 3D View's main region (whatever asked for it), with or without Show Splats
    state["redraws"] = []
    bpy.types.SpaceView3D.draw_handler_add(lambda: state["redraws"].append(now()), (), "WINDOW", "POST_PIXEL")
    log(f"setup: {state['info']}")


def _has_jobs(pkg: str) -> bool:
    try:
        mod(pkg, "blender.common.jobs")
        return True
    except ImportError:
        return False


def begin(name: str) -> None:
    state["stages"][name] = {"t0": now(), "load_start": list(os.getloadavg())}
    state["current"] = name
    log(f"{name}: start (load {os.getloadavg()[0]:.2f})")


def end(name: str, t_end: float | None = None, **info) -> None:
    st = state["stages"][name]
    st.update(t_end=t_end if t_end is not None else now(), load_end=list(os.getloadavg()), **info)
    st["wall_s"] = st["t_end"] - st["t0"]
    log(f"{name}: end after {st['wall_s']:.2f} s {info if info else ''}")


def measure_gaps(name: str) -> None:
    st = state["stages"][name]
    g = gaps(st["t0"], st["t_end"])
    st["viewport_redraws"] = sum(1 for t in state.get("redraws", []) if st["t0"] <= t <= st["t_end"])
    st.update(max_gap_s=max(g, default=0.0), gaps_over_0_2=sum(x > 0.2 for x in g), beats=len(g),
              blocked_s=sum(x for x in g if x > 0.2), **cpu_between(st["t0"], st["t_end"]))
    log(f"{name}: wall {st['wall_s']:.2f} s, longest block {st['max_gap_s']:.2f} s, "
        f"{st['gaps_over_0_2']} gaps > 0.2 s")


def wait_until(name: str, done, limit_s: float | None = None):
    """Steps polling ``done()`` (returns None, or the end time) every 50 ms; a timeout raises (ends the run)."""
    limit = state["stages"][name]["t0"] + (limit_s or STAGE_LIMIT_S)
    while True:
        box: list = []
        yield 0.05, lambda: box.append(done())
        if box and box[0] is not None:
            end(name, box[0])
            break
        if now() > limit:
            state["stages"][name].update(timeout=True, t_end=now(), wall_s=now() - state["stages"][name]["t0"])
            raise TimeoutError(f"{name} did not end within {limit_s or STAGE_LIMIT_S:.0f} s "
                               f"(jobs: {[r.status() for r in jobs_running(state['pkg'])]})")
    yield 0.3, lambda: measure_gaps(name)  # the beat after the end has come


def start_import(pkg: str) -> None:
    state["objects_before"] = set(o.name for o in bpy.data.objects)
    begin("import")
    window, area, _space, region = view3d()
    props = bpy.ops.gs_ibl.import_splats.get_rna_type().properties.keys()
    kw = {"filepath": PLY, "axis_preset": "BLENDER", "show_splats": False}
    if "from_ui" in props:
        kw["from_ui"] = True  # what the file browser's Import button runs: execute() after invoke()
    with bpy.context.temp_override(window=window, area=area, region=region):
        result = bpy.ops.gs_ibl.import_splats("EXEC_DEFAULT", **kw)
    state["stages"]["import"].update(call=sorted(result), from_ui="from_ui" in kw,
                                     call_returned_s=now() - state["stages"]["import"]["t0"])


def import_done(pkg: str):
    new = set(o.name for o in bpy.data.objects) - state["objects_before"]
    if new and not jobs_running(pkg):
        state["obj"] = sorted(new)[0]
        return now()
    return None


def start_show(pkg: str) -> None:
    collect_draws(pkg)
    begin("show")
    bpy.context.scene.gs_ibl_overlay.show = True
    redraw()


def show_done(pkg: str):
    collect_draws(pkg)
    t0 = state["stages"]["show"]["t0"]
    for t, scale, ms, dms in state["draws"]:
        if t >= t0 and ms > 0.0 and not jobs_running(pkg):
            overlay = mod(pkg, "blender.viewport.overlay")
            state["stages"]["show"].update(first_draw_ms=dms, first_render_ms=ms, scale=scale,
                                           draws_before=sum(1 for x in state["draws"] if t0 <= x[0] < t),
                                           draws_during=[(x[0] - t0, x[2], x[3]) for x in state["draws"]
                                                         if t0 <= x[0] <= t],
                                           overlay_error=overlay.error_text())
            return t + dms / 1e3
    return None


def screenshot(name: str) -> None:
    path = os.path.join(OUT, f"{name}.png")
    subprocess.run(["import", "-window", "root", path], check=False)


def start_orbit(pkg: str) -> None:
    collect_draws(pkg)
    begin("orbit")
    state["orbiting"] = True
    from mathutils import Quaternion

    def nudge() -> float | None:
        if not state.get("orbiting"):
            return None
        _w, area, space, _r = view3d()
        r3d = space.region_3d
        r3d.view_rotation = Quaternion((0.0, 0.0, 1.0), math.radians(2.0)) @ r3d.view_rotation
        area.tag_redraw()
        return 0.1

    bpy.app.timers.register(nudge, first_interval=0.0)


def orbit_done(pkg: str):
    collect_draws(pkg)
    st = state["stages"]["orbit"]
    t0 = st["t0"]
    frames = [d for d in state["draws"] if d[0] >= t0]
    if now() - t0 < ORBIT_S or len(frames) < 3:
        return None
    state["orbiting"] = False
    t1 = frames[-1][0] + frames[-1][3] / 1e3
    dms = sorted(d[3] for d in frames)
    st.update(frames=len(frames), fps=len(frames) / (t1 - t0), draw_ms_median=dms[len(dms) // 2],
              draw_ms_max=dms[-1], render_ms_median=sorted(d[2] for d in frames)[len(frames) // 2],
              scales=sorted(set(round(d[1], 3) for d in frames)), frames_log=frames)
    return t1


def start_bake(pkg: str, name: str, move: float = 0.0) -> None:
    probe = bpy.data.objects.get(state.get("probe", ""))
    if probe is None:
        bpy.context.scene.cursor.location = PROBE
        window, area, _space, region = view3d()
        with bpy.context.temp_override(window=window, area=area, region=region):
            bpy.ops.gs_ibl.add_probe(place="CURSOR")
        probe = bpy.context.active_object
        s = probe.gs_ibl_probe
        s.splats = bpy.data.objects[state["obj"]]
        s.lighting = "WORLD"  # the probe alone (the default Auto would also measure every mesh: there is none)
        state["probe"] = probe.name
        state["probe_settings"] = {"face_size": s.face_size, "method": s.method, "lighting": s.lighting}
    probe.location.x += move
    probe.gs_ibl_probe.last_report = ""
    bpy.context.view_layer.update()
    begin(name)
    window, area, _space, region = view3d()
    with bpy.context.temp_override(window=window, area=area, region=region):
        result = bpy.ops.gs_ibl.bake_probe("INVOKE_DEFAULT")
    state["stages"][name].update(call=sorted(result), call_returned_s=now() - state["stages"][name]["t0"])


def bake_done(pkg: str, name: str):
    probe = bpy.data.objects[state["probe"]]
    collect_draws(pkg)
    if jobs_running(pkg):
        return None
    report = probe.gs_ibl_probe.last_report
    t0 = state["stages"][name]["t0"]
    drawn = [d for d in state["draws"] if d[0] >= t0]  # the overlay's draws while the bake ran (main thread)
    state["stages"][name].update(report=report, ok=report.startswith("Baked"),  # an empty report: it failed
                                 overlay_draws=len(drawn), overlay_draw_s=sum(d[3] for d in drawn) / 1e3)
    return now()


def steps(pkg: str):
    state["pkg"] = pkg
    yield 1.0, lambda: setup(pkg)
    yield 2.0, lambda: start_import(pkg)
    yield from wait_until("import", lambda: import_done(pkg))
    yield 1.0, lambda: start_show(pkg)
    yield from wait_until("show", lambda: show_done(pkg))
    yield 1.0, lambda: screenshot("shown")
    yield 1.0, lambda: start_orbit(pkg)
    yield from wait_until("orbit", lambda: orbit_done(pkg))
    yield 2.0, lambda: start_bake(pkg, "bake")
    yield from wait_until("bake", lambda: bake_done(pkg, "bake"))
    yield 1.0, lambda: start_bake(pkg, "rebake", move=0.25)
    yield from wait_until("rebake", lambda: bake_done(pkg, "rebake"))
    yield 1.0, lambda: screenshot("baked")
    # the same re-bake with Show Splats off: what the viewport's redraws beside the job cost it
    yield 1.0, lambda: (setattr(bpy.context.scene.gs_ibl_overlay, "show", False), redraw())
    yield 2.0, lambda: start_bake(pkg, "rebake_hidden", move=-0.25)
    yield from wait_until("rebake_hidden", lambda: bake_done(pkg, "rebake_hidden"))


def finish(error: str | None = None) -> None:
    state["orbiting"] = False
    if error:
        log(f"failed: {error}")
    write_result(os.path.join(OUT, "capture.json"), {
        "stages": state["stages"], "info": state.get("info"), "log": state["log"],
        "probe_settings": state.get("probe_settings"), "object": state.get("obj")}, error)


start(steps, finish)
