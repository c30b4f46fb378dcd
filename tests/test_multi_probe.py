"""Many probes in one submission (SplatRenderer.render_probes, gpu_filters.filter_probes, bake_batch.bake_probes):
each probe of a batch is the single-probe render, filter and bake of its own position.

At 64^2 faces single and batched renders take the same raster path, so they agree exactly (the batch sorts the
(probe, splat) pairs by the same keys in the same stable order); at 32^2 a single probe's few tiles are rastered
in chunks and a batch's are not, which changes only float rounding and the early-termination rule (< 2e-4).
"""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.bake import BadSetting, ProbeSettings, bake_probe
from gs_ibl_addon.core.bake_batch import bake_probes
from gs_ibl_addon.core.probe import filter_probe
from gs_ibl_addon.core.probe.gpu_filters import filter_probes
from gs_ibl_addon.core.render import renderer as renderer_module
from gs_ibl_addon.core.render.renderer import (CHUNK_BYTES, CPU_RASTER_TARGET_GROUPS, SplatRenderer, probes_per_group,
                                               raster_chunks)
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene

LOD_K = 16.0  # large enough that the probes' cuts differ from the splats and from each other (~1.2k-1.5k of 3.1k)


def _shuffled(s: SplatScene, seed: int) -> SplatScene:
    m = np.random.default_rng(seed).permutation(s.count)
    return SplatScene(s.positions[m], s.scales[m], s.rotations[m], s.opacities[m], s.sh[m],
                      colour_space=s.colour_space)


def _scene(sh_degree: int) -> SplatScene:
    """A random cloud inside a coarse room (SH degree 0 walls padded to the cloud's degree), shuffled."""
    cloud = synthetic.random_scene(1500, seed=5, sh_degree=sh_degree, extent=1.5)
    room = synthetic.room_scene(spacing=0.3).scene
    k = cloud.sh.shape[1]
    sh = np.zeros((room.count, k, 3), np.float32)
    sh[:, :1] = room.sh[:, :1]
    room = SplatScene(room.positions, room.scales, room.rotations, room.opacities, sh, colour_space=cloud.colour_space)
    room.positions[:, 2] -= 1.5  # floor below the cloud
    return _shuffled(synthetic.concat([room, cloud]), sh_degree + 11)


def _origins(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.2, 1.2, (n, 3))


def _singles(r: SplatRenderer, origins: np.ndarray, face: int, lod_k: float = 0.0) -> list[np.ndarray]:
    return [np.stack(r.render(ViewBatch.cubemap(o, face), lod_k=lod_k).images) for o in origins]


@pytest.fixture(scope="module", params=[0, 3], ids=["sh0", "sh3"])
def scene(request) -> SplatScene:
    return _scene(request.param)


@pytest.mark.parametrize("lod", [False, True], ids=["full", "lod"])
@pytest.mark.parametrize("n", [1, 2, 7])
def test_each_probe_is_its_single_render(scene, lod, n):
    origins = _origins(n, seed=n)
    lod_k = LOD_K if lod else 0.0
    with SplatRenderer(scene, lod=lod) as r:
        batch = r.render_probes(origins, 64, lod_k=lod_k).frame.read_probes()
        assert batch.shape == (n, 6, 64, 64, 4)
        singles = _singles(r, origins, 64, lod_k)
        if lod:
            assert r.drawn < 0.7 * r.lod.leaves  # a real cut, not every splat
    for k in range(n):
        np.testing.assert_array_equal(batch[k], singles[k], err_msg=f"probe {k} of {n}")
    assert min(b[..., 3].mean() for b in batch) > 0.5  # something was drawn


def test_small_faces_are_their_single_renders(scene, monkeypatch):
    import gs_ibl_addon.core.render.renderer as renderer_module
    monkeypatch.setattr(renderer_module, "CPU_RASTER_TARGET_GROUPS", renderer_module.RASTER_TARGET_GROUPS)  # lavapipe too
    origins = _origins(3, seed=9)
    with SplatRenderer(scene) as r:
        batch = r.render_probes(origins, 32).frame.read_probes()
        assert 1 < r.chunks == raster_chunks(24, 3) < raster_chunks(24)  # fewer chunks than a single render
        singles = _singles(r, origins, 32)
    for k in range(3):  # other chunks than the single render: the same sums in another order
        np.testing.assert_allclose(batch[k], singles[k], rtol=0, atol=2e-4, err_msg=f"probe {k}")


def test_chunks_follow_the_workgroups_of_the_whole_group():
    assert raster_chunks(24) == 32 and raster_chunks(96) == 1
    assert raster_chunks(24, target=CPU_RASTER_TARGET_GROUPS) == 1  # a CPU device: one chunk keeps early termination
    assert raster_chunks(24, 8) == 5 and raster_chunks(24, 27) == 1 and raster_chunks(24, 53) == 1
    assert raster_chunks(24, 1, CHUNK_BYTES // 4) == 4 and raster_chunks(24, 1, 2 * CHUNK_BYTES) == 1  # bounded


def test_probe_outside_the_splats():
    scene = _scene(0)
    origins = np.array([[0.1, 0.2, 0.3], [40.0, -3.0, 2.0], [-0.5, 0.4, -0.2]])
    with SplatRenderer(scene) as r:
        res = r.render_probes(origins, 64, wait=False)
        f = filter_probes(res.frame, 8, "exact")
        batch = res.frame.read_probes()
        singles = _singles(r, origins, 64)
    for k in range(3):
        np.testing.assert_array_equal(batch[k], singles[k])
    assert f.hole_fraction[1] > 0.9 and f.hole_fraction[0] < 0.05 and f.hole_fraction[2] < 0.05


@pytest.mark.parametrize("lod, group", [(False, 2), (True, 2), (False, 1)], ids=["full-2", "lod-2", "full-1"])
def test_groups_split_to_fit_in_one_submission(monkeypatch, lod, group):
    """A device that holds 2 probes' pairs at a time: 7 probes run as groups of 2, 2, 2, 1 in one submission (or
    7 groups of 1: then one timestamp per group)."""
    scene = _scene(3)
    monkeypatch.setattr(renderer_module, "probes_per_group", lambda ctx, nodes, n, lod=False: min(n, group))
    origins = _origins(7, seed=4)
    lod_k = LOD_K if lod else 0.0
    with SplatRenderer(scene, lod=lod) as r:
        r.render_probes(origins, 64, lod_k=lod_k)  # the first may redraw once with room for more instances
        submits = r.ctx.stats.submits
        res = r.render_probes(origins, 64, lod_k=lod_k, timestamps=True)
        assert r.ctx.stats.submits - submits == 1 and r.slots == group
        if r.ctx.timestamps_supported:
            assert ("probes" in res.timings_ms) == (group == 1) and res.timings_ms["total"] > 0
        batch = res.frame.read_probes()
        singles = _singles(r, origins, 64, lod_k)
    for k in range(7):
        np.testing.assert_array_equal(batch[k], singles[k], err_msg=f"probe {k}")


def test_capacity_overflow_recovered():
    scene = _scene(0)
    scene.scales *= 5.0  # big splats: many more tile instances than the first capacity
    origins = _origins(4, seed=2)
    with SplatRenderer(scene) as r:
        first = r.capacity
        res = r.render_probes(origins, 64, wait=False)
        f = filter_probes(res.frame, 8, "exact")  # queued behind a render that must be drawn again: filtered again
        assert res.instances > first and r.capacity > first
        batch = res.frame.read_probes()
        singles = _singles(r, origins, 64)
        single_irr = [filter_probe(c, 8, "exact", roughness=None, use_gpu=True, vk_context=r.ctx).irradiance
                      for c in singles]
    for k in range(4):
        np.testing.assert_array_equal(batch[k], singles[k])
        np.testing.assert_allclose(f.irradiance[k], single_irr[k], rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("method", ["exact", "sh"])
def test_batched_filter_is_the_single_filter(method):
    scene = _scene(3)
    origins = _origins(3, seed=7)
    with SplatRenderer(scene) as r:
        f = filter_probes(r.render_probes(origins, 64, wait=False).frame, 8, method)
        single = [filter_probe(r.render(ViewBatch.cubemap(o, 64)).frame, 8, method, roughness=None) for o in origins]
    for k, p in enumerate(single):
        np.testing.assert_allclose(f.sh_coefficients[k], p.sh_coefficients, rtol=0, atol=1e-12)
        np.testing.assert_allclose(f.irradiance[k], p.irradiance, rtol=1e-6, atol=1e-9)
        assert f.hole_fraction[k] == pytest.approx(p.hole_fraction, abs=1e-12)


def test_bake_probes_is_bake_probe_at_each_position():
    scene = _scene(0)
    origins = np.concatenate([_origins(2, seed=8), [[30.0, 0.0, 0.0]]])  # the last sees mostly holes: filled
    s = ProbeSettings(face_size=64, irradiance_size=8)
    with SplatRenderer(scene) as r:
        many = bake_probes(None, origins, s, renderer=r)
        for k, o in enumerate(origins):
            one = bake_probe(None, o, s, renderer=r)
            np.testing.assert_allclose(many[k].irradiance, one.irradiance, rtol=1e-6, atol=1e-9)
            np.testing.assert_allclose(many[k].sh_coefficients, one.sh_coefficients, rtol=1e-6, atol=1e-9)
            assert many[k].hole_fill["fraction"] == pytest.approx(one.hole_fill["fraction"])
            assert many[k].settings["probe_position"] == [float(x) for x in o]
        grid = bake_probes(None, origins[:2], ProbeSettings(irradiance_size=4, max_face_size=64), renderer=r,
                           keep_radiance=False)
    assert [t["face_size"] for t in grid[0].settings["face_size_trials"]] == [32, 64]
    assert grid[0].radiance is None and grid[0].irradiance.shape == (6, 4, 4, 3)


@pytest.mark.parametrize("positions, words", [
    (np.zeros((0, 3)), "at least one"),
    ([[0.0, 0.0, 0.0], [np.nan, 1.0, 2.0]], "probe 1"),
    ([[0.0, 0.0]], "(N, 3)"),
    ("here", "three numbers"),
])
def test_bad_positions_are_refused_before_any_work(positions, words):
    with pytest.raises(BadSetting, match=None) as e:
        bake_probes(_scene(0), positions, ProbeSettings(face_size=32))
    assert words in str(e.value) and e.value.option == "probes"
    with pytest.raises(ValueError):
        ViewBatch.cubemaps(positions, 32)


def test_group_size_fits_the_device():
    with SplatRenderer(synthetic.random_scene(10, seed=1)) as r:
        limits = r.ctx.vk.vkGetPhysicalDeviceProperties(r.ctx.physical_device).limits
        assert probes_per_group(r.ctx, 1000, 125) == 125
        huge = probes_per_group(r.ctx, 50_000_000, 125)
        assert 1 <= huge < 125 and huge * 50_000_000 * 80 <= max(limits.maxStorageBufferRange, 50_000_000 * 80)


def test_single_probe_filters_refuse_a_batch_frame():
    """A filter of one probe given a frame of several would read the first probe only: it says what to use."""
    with SplatRenderer(_scene(0)) as r:
        frame = r.render_probes(_origins(2), 32).frame
        with pytest.raises(ValueError, match="filter_probes"):
            filter_probe(frame, 8, "exact", roughness=None)
        with pytest.raises(ValueError, match="read_probes"):
            frame.read_cube()


def test_a_frame_too_big_for_the_device_is_refused_before_drawing():
    from gs_ibl_addon.core.render.renderer import largest_probe_face
    scene = _scene(0)
    with SplatRenderer(scene) as r:
        n = 1000
        face = 2 * largest_probe_face(r.ctx, n)
        generation = r.generation
        with pytest.raises(ValueError, match=f"use faces of {face // 2}"):
            r.render_probes(_origins(n), face)
        assert r.generation == generation  # nothing was drawn
        with pytest.raises(BadSetting, match="do not fit") as e:
            bake_probes(None, _origins(n), ProbeSettings(face_size=face), renderer=r)
        assert e.value.option == "face_size"


def test_trim_keeps_a_small_batch_within_its_share():
    """trim(keep_within): a batch's buffers within that share of the device's heap are kept (a renderer kept between
    bakes makes them and records its programs again otherwise); past it they are given back."""
    from gs_ibl_addon.core.limits import device_local_bytes
    with SplatRenderer(_scene(0)) as r:
        r.render_probes(_origins(7, seed=3), 64)
        held = r.held_bytes()
        assert r.slots == 7 and 0 < held < device_local_bytes(r.ctx)
        r.trim(keep_within=1.0)
        assert r.slots == 7 and r.held_bytes() == held and r._frame
        r.trim(keep_within=0.5 * held / device_local_bytes(r.ctx))
        assert r.slots == 1 and not r._frame and r.held_bytes() < held


@pytest.mark.parametrize("lod", [False, True], ids=["full", "lod"])
def test_trim_gives_back_what_a_batch_grew(lod):
    scene = _scene(0)
    o = _origins(7, seed=3)
    with SplatRenderer(scene, lod=lod) as r:
        slots, capacity = r.slots, r.capacity
        before = _singles(r, o[:1], 64, LOD_K if lod else 0.0)[0]
        frame = r.render_probes(o, 64, lod_k=LOD_K if lod else 0.0).frame
        assert r.slots == 7 and r.capacity > capacity
        r.trim()
        assert (r.slots, r.capacity) == (slots, capacity) and not r._frame  # the batch's frame buffers too
        with pytest.raises(Exception, match="overwritten"):
            frame.read_probes()
        np.testing.assert_array_equal(_singles(r, o[:1], 64, LOD_K if lod else 0.0)[0], before)
