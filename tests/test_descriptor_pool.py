"""A kernel's descriptor pool that fills (pipelines.py) is retired, never reset while a recording, a submission
in flight or a kept program binds one of its sets: a later recording resets it once none does (context.pool_users).
Each case below forces it with a pool of 6 sets: a renderer's frames (the whole suite once hit 'recorded program is
stale' in a bake), one one-shot recording that binds more sets than a pool holds, and a render submitted without
waiting (render(wait=False)) whose filter is recorded behind it."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core.probe import filter_probe
from gs_ibl_addon.core.render.gpu_sort import Scanner
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.synthetic import random_scene
from gs_ibl_addon.core.vk import Buffer, Recorder, VulkanContext, pipelines

SIZES = (16, 24, 32, 40, 48, 56)


def _scan_pipelines(ctx, what: str) -> list:
    """``what`` of the prefix sum's pipelines (the kernels these tests record)."""
    return [getattr(p, what) for p in ctx._pipelines.values() if p.name.startswith("scan_")]


@pytest.fixture
def own_context():
    """A context of the test's own: the shared one's kept programs (other tests' renderers and filter plans) may
    hold pools that these tests expect to see reset."""
    with VulkanContext() as ctx:
        yield ctx


@pytest.fixture
def small_pools(monkeypatch):
    monkeypatch.setattr(pipelines.Pipeline, "POOL_SETS", 6)


def test_frames_survive_a_pool_filling_while_recording(monkeypatch):
    scene = random_scene(3000, seed=5, sh_degree=1)
    with SplatRenderer(scene) as r:
        want = [np.array(r.render(ViewBatch.cubemap([0, 0, 0], s)).images) for s in SIZES]
    # a pool of a few sets fills within a recording or two: every frame below meets a full pool somewhere
    monkeypatch.setattr(pipelines.Pipeline, "POOL_SETS", 6)
    with SplatRenderer(scene) as r:
        for _ in range(2):
            for s, w in zip(SIZES, want):
                got = np.array(r.render(ViewBatch.cubemap([0, 0, 0], s)).images)
                np.testing.assert_array_equal(got, w)


def test_one_recording_binds_more_sets_than_a_pool_holds(small_pools, own_context):
    ctx = own_context
    rng = np.random.default_rng(3)
    data = [rng.integers(0, 100, 1000).astype(np.uint32) for _ in range(10)]
    bufs = [Buffer(ctx, 4000, f"scan{i}") for i in range(10)]
    scanner = Scanner(ctx, 1000)
    try:
        for b, d in zip(bufs, data):
            b.write(d)
        with Recorder(ctx) as rec:  # ten scans' sets of one kernel: the pool fills twice within this recording
            for b in bufs:
                scanner.record(rec, b, 1000)
            retired = {p.name: p.retired for p in ctx._pipelines.values() if p.retired}
            assert retired  # full pools were set aside, not reset under the recording
        for b, d in zip(bufs, data):
            np.testing.assert_array_equal(b.read(np.uint32, 1000), np.cumsum(d) - d)
        with Recorder(ctx):  # the next recording: the pools nothing uses any more are reset
            pass
        assert not any(_scan_pipelines(ctx, "retired"))
    finally:
        scanner.destroy()
        for b in bufs:
            b.destroy()


def test_a_render_in_flight_keeps_its_sets(monkeypatch):
    scene = random_scene(3000, seed=7, sh_degree=1)
    settings = dict(irradiance_size=8, method="exact", roughness=None, read_radiance=False)
    with SplatRenderer(scene) as r:
        want = [filter_probe(r.render(ViewBatch.cubemap([0, 0, 0], s)).frame, **settings).irradiance
                for s in SIZES]
    monkeypatch.setattr(pipelines.Pipeline, "POOL_SETS", 6)
    with SplatRenderer(scene) as r:
        for _ in range(2):
            for s, w in zip(SIZES, want):
                res = r.render(ViewBatch.cubemap([0, 0, 0], s), wait=False)
                # the filter records (and fills pools) while the render is in flight
                got = filter_probe(res.frame, **settings).irradiance
                np.testing.assert_array_equal(got, w)


def test_a_kept_program_keeps_its_pool(small_pools, own_context):
    """A program recorded, then a recording that fills the pool and later ones: the program's sets stay (its pool is
    in use while it lives) and it runs as recorded; once it is closed its pool is reset."""
    ctx = own_context
    rng = np.random.default_rng(4)
    data = [rng.integers(0, 100, 1000).astype(np.uint32) for _ in range(10)]
    bufs = [Buffer(ctx, 4000, f"kept{i}") for i in range(10)]
    scanner = Scanner(ctx, 1000)
    try:
        rec = Recorder(ctx, reusable=True)
        scanner.record(rec, bufs[0], 1000)
        prog = rec.program()
        for b in bufs[1:]:  # each its own recording: the pool fills and later recordings look for pools to reset
            with Recorder(ctx) as r:
                scanner.record(r, b, 1000)
        bufs[0].write(data[0])
        prog.run()
        np.testing.assert_array_equal(bufs[0].read(np.uint32, 1000), np.cumsum(data[0]) - data[0])
        assert prog.valid and any(_scan_pipelines(ctx, "retired"))  # the program's pool is still set aside
        prog.close()
        with Recorder(ctx):
            pass
        assert not any(_scan_pipelines(ctx, "retired"))
    finally:
        scanner.destroy()
        for b in bufs:
            b.destroy()
