"""The GPU stages' boundaries: render -> GpuFrame -> filters without a host round trip, frame resources reused, and
contexts passed explicitly. Transfers are counted by the context (VulkanContext.stats), not guessed."""
import numpy as np
import pytest

from gs_ibl_addon.core.probe import filter_probe
from gs_ibl_addon.core.probe import gpu_filters as gf
from gs_ibl_addon.core.render.renderer import SplatRenderer, StaleFrame
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.synthetic import random_scene
from gs_ibl_addon.core.vk import VulkanContext, VulkanUnavailable, get_context
from gs_ibl_addon.core.vk.constants import VIEW_BYTES


@pytest.fixture(scope="module")
def ctx():
    try:
        with VulkanContext() as c:
            yield c
    except VulkanUnavailable as e:
        pytest.skip(str(e))


@pytest.fixture(scope="module")
def renderer(ctx):
    with SplatRenderer(random_scene(3000, seed=3, sh_degree=1, extent=4.0), ctx) as r:
        yield r


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("method", ["exact", "sh", "box", "convolve"])
def test_frame_filters_like_the_read_back_cube(renderer, method):
    kw = dict(irradiance_size=8, method=method, roughness=None, phi_steps=16, theta_steps=4, box_level_size=2)
    frame = renderer.render(ViewBatch.cubemap([0.1, -0.2, 0.05], 32)).frame
    cube = np.stack(frame.read_images())
    on_gpu = filter_probe(frame, **kw)
    via_host = filter_probe(cube, use_gpu=True, vk_context=renderer.ctx, **kw)
    assert _rel(on_gpu.irradiance, via_host.irradiance) < 2e-5
    assert _rel(on_gpu.sh_coefficients, via_host.sh_coefficients) < 2e-5
    assert abs(on_gpu.hole_fraction - via_host.hole_fraction) < 1e-5 and via_host.hole_fraction > 0
    np.testing.assert_array_equal(on_gpu.radiance, cube)


def test_filter_queued_behind_a_render_that_must_be_drawn_again(ctx):
    # render(wait=False) + filter: the instance list outgrows the first capacity, the render is drawn again and the
    # filter queued behind the first attempt runs again: the result equals the waited, read-back path.
    scene = random_scene(3000, seed=4, sh_degree=0, extent=2.0)
    scene.scales *= 6.0
    batch = ViewBatch.cubemap([0.0, 0.0, 0.0], 64)
    with SplatRenderer(scene, ctx) as r:
        first_capacity = r.capacity
        res = r.render(batch, wait=False)
        on_gpu = filter_probe(res.frame, 8, "exact", roughness=None)
        assert res.instances > first_capacity and r.capacity > first_capacity
        via_host = filter_probe(np.stack(r.render(batch).images), 8, "exact", roughness=None, use_gpu=True,
                                vk_context=ctx)
    assert _rel(on_gpu.irradiance, via_host.irradiance) < 2e-5


def test_probe_reads_back_only_the_small_results(renderer):
    ctx, batch = renderer.ctx, ViewBatch.cubemap([0.0, 0.0, 0.0], 64)
    for _ in range(2):  # the first records the programs and uploads the tables
        filter_probe(renderer.render(batch).frame, 16, "exact", roughness=None, read_radiance=False)
    before = ctx.stats.snapshot()
    p = filter_probe(renderer.render(batch, wait=False).frame, 16, "exact", roughness=None, read_radiance=False)
    d = ctx.stats.since(before)
    assert p.radiance is None and p.irradiance.shape == (6, 16, 16, 3)
    radiance_bytes = 6 * 64 * 64 * 16
    small = 6 * 16 * 16 * 12 + gf.SH_GROUPS_MAX * (27 + 1) * 4 + 64
    assert d["readback_bytes"] <= small < radiance_bytes // 10, d
    assert d["upload_bytes"] <= 6 * VIEW_BYTES + 16, d  # the views and the probe position, nothing else
    assert d["submits"] == 1, d  # the recorded render and the recorded filter, in one vkQueueSubmit (commands.flush)


def test_frame_resources_are_reused(renderer):
    ctx, batch = renderer.ctx, ViewBatch.cubemap([0.0, 0.0, 0.0], 16)
    for _ in range(2):  # the second frame is recorded for what the first drew (SplatRenderer._caps)
        renderer.render(batch, timestamps=True)
        gf.gpu_exact_irradiance(renderer.last_frame, 4)
    pools = (len(ctx._free_fences), len(ctx._free_cmds), len(ctx._free_queries))
    for _ in range(3):
        renderer.render(batch, timestamps=True)
        gf.gpu_exact_irradiance(renderer.last_frame, 4)
    assert (len(ctx._free_fences), len(ctx._free_cmds), len(ctx._free_queries)) == pools


def test_stale_frame_refuses_to_be_read(renderer):
    first = renderer.render(ViewBatch.cubemap([0.0, 0.0, 0.0], 8)).frame
    renderer.render(ViewBatch.cubemap([0.5, 0.0, 0.0], 8))
    with pytest.raises(StaleFrame):
        first.read_images()
    with pytest.raises(StaleFrame):
        filter_probe(first, 4, "exact", roughness=None)


def test_depth_only_when_asked(renderer):
    batch = ViewBatch.pinhole([0, -6, 0], [0, 0, 0], 50, 24, 16)
    res = renderer.render(batch)
    assert res.frame.depth is None
    with pytest.raises(ValueError, match="depth=True"):
        res.depths
    assert renderer.render(batch, depth=True).depths[0].shape == (16, 24)


def test_another_device_request_leaves_the_shared_context_open():
    shared = get_context()
    try:
        other = get_context("cpu")
    except VulkanUnavailable:
        pytest.skip("no CPU Vulkan device here")
    assert shared.device is not None and get_context() is shared
    assert other.device is not None


def test_latlong_of_a_frame_matches_the_read_back_cube(renderer):
    from gs_ibl_addon.core.probe import cube_to_latlong
    frame = renderer.render(ViewBatch.cubemap([0.2, 0.1, 0.0], 16)).frame
    img, _ = gf.gpu_cube_to_latlong(frame, 64)
    ref = cube_to_latlong(np.stack(frame.read_images())[..., :3], 64)
    assert _rel(img, ref) < 2e-5


def test_device_local_buffers_go_through_the_kept_staging_buffers(ctx, monkeypatch):
    # A discrete GPU's large buffers are not mapped: writes and reads go through the context's two staging buffers,
    # in pieces of at most STAGING_MAX. lavapipe maps everything, so the path is forced here by unmapping.
    from gs_ibl_addon.core.vk import Buffer, buffers
    monkeypatch.setattr(buffers, "STAGING_MAX", 4096)
    data = np.random.default_rng(1).random(5000).astype(np.float32)  # 20000 bytes: five pieces
    with Buffer(ctx, data.nbytes + 64, "device-local") as b:
        ctx.vk.vkUnmapMemory(ctx.device, b.memory)
        b._map = None
        b.write(data, 64)
        np.testing.assert_array_equal(b.read(np.float32, 5000, 64), data)
    assert ctx._staging["up"].nbytes >= 4096 and ctx._staging["down"].nbytes >= 4096


@pytest.mark.parametrize("mapped", [True, False])
def test_large_transfers_split_over_threads_arrive_whole(ctx, monkeypatch, mapped):
    # A GPU machine's host copies a large readback or upload over COPY_THREADS threads (buffers.copy_bytes); this
    # 2-core machine does not, so the split is forced: pieces of whole pages, the last short, every byte in place.
    from gs_ibl_addon.core.vk import Buffer, buffers
    monkeypatch.setattr(buffers, "PARALLEL_COPY", 4096)
    monkeypatch.setattr(buffers, "COPY_THREADS", 3)
    data = np.random.default_rng(2).random(50_001).astype(np.float32)  # 200,004 bytes: 3 pieces, not of a page
    with Buffer(ctx, data.nbytes + 64, "copies") as b:
        if not mapped:
            ctx.vk.vkUnmapMemory(ctx.device, b.memory)
            b._map = None
        b.write(data, 64)
        out = np.full(len(data), -1.0, np.float32)
        assert b.read(np.float32, len(data), 64, out=out) is out
        np.testing.assert_array_equal(out, data)


def test_filter_plans_of_a_closed_renderer_give_their_buffers_back(ctx):
    scene = random_scene(500, seed=6, sh_degree=0, extent=3.0)
    with SplatRenderer(scene, ctx) as r:
        filter_probe(r.render(ViewBatch.cubemap([0, 0, 0], 16)).frame, 4, "exact", roughness=None)
        stale = [v for k, v in ctx.cache.items() if k[0] == "filter-plan" and k[1] == r.last_frame.image.serial]
    assert stale and not stale[0].valid
    with SplatRenderer(scene, ctx) as r2:  # the next plan made drops the stale one
        filter_probe(r2.render(ViewBatch.cubemap([0, 0, 0], 16)).frame, 4, "exact", roughness=None)
    assert all(v is not stale[0] for v in ctx.cache.values())
