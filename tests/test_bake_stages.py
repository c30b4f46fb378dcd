"""A bake reports each stage's wall time beside the GPU time of the submissions it waited for
(core/stage_times.py), and the face-size search's per-face parts taken on a GPU equal the numpy reference."""
from __future__ import annotations

import numpy as np

from gs_ibl_addon.core.bake import ProbeSettings, bake_probe, irradiance_parts
from gs_ibl_addon.core.bake_batch import bake_probes
from gs_ibl_addon.core.probe.reference import exact_irradiance_parts
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.stage_times import StageTimes, stage_text, stages
from gs_ibl_addon.core.synthetic import random_scene
from gs_ibl_addon.core.vk import get_context


def test_stage_times_add_up_and_count_gpu_time():
    ctx = get_context()
    scene = random_scene(2000, seed=3, sh_degree=0)
    with SplatRenderer(scene, ctx) as r:
        result = bake_probe(None, [0.1, 0.0, 0.0], ProbeSettings(face_size=0, irradiance_size=0), renderer=r,
                            host_splats=scene)
        rows = stages(result.timings_ms)
        assert {"search", "radiance readback", "holes and lights", "irradiance size", "near splats"} <= set(rows)
        for row in rows.values():
            assert 0 <= row["gpu"] <= row["wall"] + 1e-6 and row["host"] >= 0
        # the stages cover the bake: together within its wall time, and the search's submissions were timed
        assert sum(row["wall"] for row in rows.values()) <= result.timings_ms["bake_wall"] + 1e-6
        assert rows["search"]["submits"] >= 2 and rows["search"]["gpu"] > 0
        assert "search" in stage_text(result.timings_ms)
        batch = bake_probes(None, [[0, 0, 0], [0.2, 0, 0]], ProbeSettings(face_size=16, irradiance_size=4),
                            renderer=r)
        assert stages(batch[0].timings_ms)["render"]["submits"] >= 1


def test_stamp_all_times_unstamped_submissions():
    ctx = get_context()
    timings: dict[str, float] = {}
    scene = random_scene(500, seed=4, sh_degree=0)
    old = ctx.stamp_all
    ctx.stamp_all = True
    try:
        with SplatRenderer(scene, ctx) as r, StageTimes(ctx, timings).stage("render"):
            res = r.render_probes(np.zeros((1, 3)), 16)  # no timestamps asked: none reported, all counted
        assert res.timings_ms == {} or "total" not in res.timings_ms
    finally:
        ctx.stamp_all = old
    assert timings["stage:render:gpu"] > 0 and timings["stage:render:submits"] >= 1


def test_irradiance_parts_on_a_gpu_equal_the_reference(monkeypatch):
    ctx = get_context()
    change = np.random.default_rng(1).normal(size=(6, 32, 32, 3)) * 0.1
    want = exact_irradiance_parts(change, 8)
    monkeypatch.setattr(ctx, "is_cpu", False)  # the GPU path, on whatever device runs the tests
    got = irradiance_parts(change, 8, ctx)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())
