"""Deep tiles on a device that ends long loops: llvmpipe (lavapipe) stops every loop of a shader invocation once all
of them together have run 65,535 iterations (Mesa's LP_MAX_TGSI_LOOP_ITERATIONS, shared between every loop), with no
error. A raster workgroup whose list holds more pairs than that composited only the first ~65k: a 1M-splat shell at
16² faces came out 0.987 covered where the numpy reference is 0.995. The renderer learns each frame's deepest chunk and,
on a CPU device, draws it again in chunks short enough (renderer.LOOP_PAIRS). Checked here against the same frame in
many short chunks (which the limit never reaches), one 16x16 tile of ~94k pairs, the splats stored in random order."""
import numpy as np
import pytest

from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc
from gs_ibl_addon.core.vk import get_context


def _deep_tile(n: int = 100_000, seed: int = 5) -> tuple[SplatScene, ViewBatch]:
    """A shell segment 5-6 m down +X filling a 70-degree 16x16 view (one tile): sub-pixel splats of opacity 0.006,
    so that no pixel turns opaque and the pairs past the 65,535th still show (~20% of each pixel's coverage)."""
    rng = np.random.default_rng(seed)
    f32 = np.float32
    d = np.column_stack([np.ones(n), rng.uniform(-0.75, 0.75, (n, 2))]).astype(f32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pos = d * rng.uniform(5.0, 6.0, n).astype(f32)[:, None]
    rot = rng.standard_normal((n, 4)).astype(f32)
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    sh = rgb_to_sh_dc(rng.uniform(0.1, 0.9, (n, 3)).astype(f32))[:, None, :]
    scene = SplatScene(pos.astype(f32), np.full((n, 3), 0.02, f32), rot, np.full(n, 0.006, f32), sh.astype(f32),
                       colour_space="linear")
    return scene, ViewBatch.pinhole(np.zeros(3), np.array([1.0, 0, 0]), 70.0, 16, 16)


def _render(monkeypatch, scene, batch, target_groups: int):
    monkeypatch.setattr(R, "CPU_RASTER_TARGET_GROUPS", target_groups)
    monkeypatch.setattr(R, "RASTER_TARGET_GROUPS", target_groups)
    r = R.SplatRenderer(scene, get_context())
    try:
        res = r.render(batch, depth=True)
        return res.images[0], res.depths[0], r.chunks, int(r.count.read(np.uint32, 1)[0])
    finally:
        r.close()


def test_a_tile_deeper_than_the_loop_limit(monkeypatch):
    scene, batch = _deep_tile()
    deep, deep_z, deep_chunks, pairs = _render(monkeypatch, scene, batch, 1)  # one chunk unless the limit asks
    short, short_z, short_chunks, _ = _render(monkeypatch, scene, batch, 64)  # 32 chunks of ~2.5k pairs
    assert pairs > 90_000 and short_chunks == R.MAX_RASTER_CHUNKS
    if get_context().is_cpu:
        assert deep_chunks * R.LOOP_PAIRS["gs_raster"] >= pairs > R.LOOP_PAIRS["gs_raster"]
    assert np.abs(deep - short).max() < 1e-5  # the chunk merge's rounding
    covered = short[..., 3] > 0.05
    assert covered.all() and short[..., 3].mean() < 0.995  # pixels not opaque early: late pairs count
    np.testing.assert_allclose(deep_z[covered], short_z[covered], rtol=1e-5)
