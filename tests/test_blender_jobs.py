"""Long work beside Blender's UI (blender/common/jobs.py): a job's Work runs on a worker thread while the main thread
keeps ticking, progress comes back, errors reach the job, Esc (cancel) stops the worker at its next progress call
and leaves the scene as it was; the bake as a job writes exactly what the bake run now writes."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from gs_ibl_addon.blender.common import jobs  # noqa: E402
from gs_ibl_addon.core.synthetic import SkyGradient, shell_scene  # noqa: E402


def _drive(runner: jobs.Runner, timeout: float = 300.0, on_tick=None, budget_s: float = 0.05) -> int:
    """Tick ``runner`` as the modal operator's timer would, until it ends; returns how many ticks it took.
    ``budget_s=0``: a tick at every Step (as on a slow machine, where each main-thread piece fills a tick)."""
    ticks, end = 0, time.monotonic() + timeout
    while not runner.tick(budget_s):
        ticks += 1
        if on_tick is not None:
            on_tick(runner, ticks)
        assert time.monotonic() < end, f"job still running after {timeout} s: {runner.text}"
        time.sleep(0.01)
    return ticks


def test_work_runs_on_a_worker_while_the_main_thread_ticks():
    main = threading.get_ident()
    seen = {}

    def work(n, progress):
        seen["thread"] = threading.get_ident()
        for i in range(n):
            progress(f"part {i}", i / n)
            time.sleep(0.02)
        return n * 2

    def job():
        yield jobs.Step("before", 0.1)
        value = yield jobs.Work(work, 10, span=(0.1, 0.9))
        yield jobs.Step("after", 0.95)
        return value + 1

    runner = jobs.Runner(job(), "testing")
    fractions = []
    ticks = _drive(runner, on_tick=lambda r, _: fractions.append(r.fraction))
    assert runner.done and not runner.cancelled and runner.error is None and runner.result == 21
    assert seen["thread"] != main
    assert ticks >= 5  # the main thread came back while the worker ran (10 x 20 ms)
    assert any(0.1 < f < 0.9 for f in fractions)  # the worker's progress, mapped into its span
    assert jobs.run_now(job()) == 21  # the same job run now gives the same result


def test_a_workers_error_is_raised_in_the_job_at_its_yield():
    def work(progress):
        raise ValueError("bad splats: do this")

    def job():
        try:
            yield jobs.Work(work)
        except ValueError as e:
            return f"caught {e}"

    runner = jobs.Runner(job(), "testing")
    _drive(runner)
    assert runner.result == "caught bad splats: do this"

    def uncaught():
        yield jobs.Work(work)

    runner = jobs.Runner(uncaught(), "testing")
    _drive(runner)
    assert isinstance(runner.error, ValueError) and "do this" in str(runner.error)
    with pytest.raises(ValueError, match="do this"):
        jobs.run_now(uncaught())


def test_cancel_stops_the_worker_and_runs_the_jobs_finally_without_writing():
    state = {"written": False, "cleaned": False, "calls": 0}

    def work(progress):
        for i in range(1000):
            state["calls"] = i
            progress("working", i / 1000)
            time.sleep(0.005)
        return "all"

    def job():
        try:
            yield jobs.Work(work)
            state["written"] = True  # the job's writing part: must not run once cancelled
        finally:
            state["cleaned"] = True

    runner = jobs.Runner(job(), "testing")
    _drive(runner, on_tick=lambda r, n: r.cancel() if n == 3 else None)
    assert runner.cancelled and runner.done and not state["written"] and state["cleaned"]
    assert state["calls"] < 500  # stopped at a progress call, not after the whole work
    assert "cancel" in runner.status() or runner.text == "cancelled"


def test_the_gpu_is_held_by_the_worker_only_while_it_works():
    held = {}

    def work(progress):
        time.sleep(0.2)
        return 1

    def job():
        yield jobs.Work(work)

    def look(runner, _n):
        if runner.working:
            got = jobs.gpu.acquire(blocking=False)  # from the main thread, as the overlay's draw does
            held.setdefault("during", not got)
            if got:
                jobs.gpu.release()

    _drive(jobs.Runner(job(), "testing"), on_tick=look)
    assert held["during"]  # the overlay draws its last images instead of rendering under the worker
    assert jobs.gpu.acquire(blocking=False)
    jobs.gpu.release()


@pytest.fixture
def shell_probe(blender, tmp_path, write_3dgs_ply):
    path = tmp_path / "shell.ply"
    write_3dgs_ply(path, shell_scene(SkyGradient(), 6000, 5.0, (0.0, 0.0, 0.0)))
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), axis_preset="BLENDER",
                                        show_proxy=False) == {"FINISHED"}
    splats = bpy.context.active_object
    splats.gs_ibl_splats.colour_space = "LINEAR"
    bpy.ops.gs_ibl.add_probe(place="CURSOR")
    probe = bpy.context.active_object
    probe.gs_ibl_probe.face_size, probe.gs_ibl_probe.irradiance_size = 32, 8
    probe.gs_ibl_probe.lighting = "WORLD"
    return probe, splats


def _world_pixels():
    from gs_ibl_addon.blender.lighting import world as gw
    return gw.image_latlong_pixels(bpy.context.scene.world.node_tree.nodes["GS-IBL Radiance"].image)


def test_the_bake_as_a_job_beside_the_ui_writes_what_the_bake_run_now_writes(shell_probe):
    from gs_ibl_addon.blender.lighting import bake as gb
    probe, splats = shell_probe
    scene = bpy.context.scene
    runner = jobs.Runner(gb.bake_job(scene, probe, splats), "baking")
    texts = set()
    ticks = _drive(runner, on_tick=lambda r, _: texts.add(r.text))
    assert runner.error is None and not runner.cancelled, runner.error
    result, text, _warning = runner.result
    assert ticks >= 2 and "Baked 6,000 splats" in text
    assert any("cubemap" in t or "reading" in t for t in texts)  # the stages were seen while it ran
    by_job = _world_pixels()
    gb.bake_into_world(scene, probe, splats)
    np.testing.assert_array_equal(_world_pixels(), by_job)


def test_a_cancelled_bake_leaves_the_world_and_images_as_they_were(shell_probe):
    from gs_ibl_addon.blender.lighting import bake as gb
    probe, splats = shell_probe
    scene = bpy.context.scene
    before_world = scene.world
    before_images = set(bpy.data.images.keys())
    before_report = probe.gs_ibl_probe.last_report
    probe.gs_ibl_probe.face_size = 128  # long enough to be cancelled while it renders
    runner = jobs.Runner(gb.bake_job(scene, probe, splats), "baking")
    _drive(runner, on_tick=lambda r, _: r.cancel() if r.working else None)
    assert runner.cancelled and runner.result is None
    assert scene.world == before_world and set(bpy.data.images.keys()) == before_images
    assert probe.gs_ibl_probe.world is None and probe.gs_ibl_probe.last_report == before_report


def test_a_probe_deleted_while_its_bake_runs_is_not_written(shell_probe):
    from gs_ibl_addon.blender.lighting import bake as gb
    probe, splats = shell_probe
    scene = bpy.context.scene
    runner = jobs.Runner(gb.bake_job(scene, probe, splats), "baking")

    def delete(r, _n):
        if r.working and scene.objects.get("GS-IBL Probe") is not None:
            bpy.data.objects.remove(scene.objects["GS-IBL Probe"])

    _drive(runner, on_tick=delete)
    assert isinstance(runner.error, ValueError) and "deleted while it was being baked" in str(runner.error)
    assert not any(i.startswith("gs_ibl_") for i in bpy.data.images.keys())


def test_start_without_a_window_runs_now():
    done = []

    def job():
        value = yield jobs.Work(lambda progress: 5)
        return value

    assert jobs.start("test", job(), "testing", done=lambda r: done.append(r.result)) is None
    assert done == [5] and jobs.busy("test") is None


def test_an_import_cancelled_while_it_makes_its_objects_leaves_no_datablock(blender, tmp_path, write_3dgs_ply):
    """Two files: the first object made, the second cancelled between two of its attributes: neither stays."""
    from gs_ibl_addon.blender.splats.importer import _import_steps
    paths = []
    for i in range(2):
        paths.append(str(tmp_path / f"shell{i}.ply"))
        write_3dgs_ply(paths[-1], shell_scene(SkyGradient(), 3000, 5.0, (0.0, 0.0, 0.0)))
    before = (set(bpy.data.objects.keys()), set(bpy.data.meshes.keys()))
    job = _import_steps(paths, [np.identity(4)] * 2, None, False, False, False)
    runner = jobs.Runner(job, "importing")

    def cancel(r, _n):
        if "making shell1" in r.text:
            r.cancel()

    _drive(runner, on_tick=cancel, budget_s=0.0)
    assert runner.cancelled
    assert (set(bpy.data.objects.keys()), set(bpy.data.meshes.keys())) == before
    # the same import left to finish makes both
    assert len(jobs.run_now(_import_steps(paths, [np.identity(4)] * 2, None, False, False, False))) == 2
    assert {"shell0", "shell1"} <= set(bpy.data.objects.keys())


def test_a_bake_run_now_advances_the_upload_it_waits_for(shell_probe):
    """A script's bake (run now, the main thread held) while Show Splats' upload of the same object is a background
    job: the bake advances that job itself (its timer cannot run meanwhile) instead of waiting forever, and the
    splats are read and uploaded once. (A reload in Blender 5.2's GUI once hung here: the redraw after loading
    started the upload, the scenario's next step baked.)"""
    from gs_ibl_addon.blender.lighting import bake as gb
    from gs_ibl_addon.blender.splats import cache as splat_cache
    probe, splats = shell_probe
    key = splat_cache.upload_key(splats)
    uploads = splat_cache.uploads
    runner = jobs.Runner(splat_cache.get_steps(splats, wait_for_upload=False), "showing")
    runner.tick(0.0)  # begun: it has read a piece
    assert not runner.done
    jobs._background[key] = runner
    try:
        _result, text, _warning = gb.bake_into_world(bpy.context.scene, probe, splats)
    finally:
        jobs._background.pop(key, None)
    assert runner.done and runner.error is None and text.startswith("Baked 6,000 splats")
    assert splat_cache.uploads == uploads + 1
