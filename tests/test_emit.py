"""The two ways of emitting (tile, splat) instances (shaders/gs_emit.glsl): one thread per instance slot (GPUs) and
one thread per splat (CPU devices, renderer.EMIT_PER_SPLAT). Both fill slot offsets[j] + r with splat j's r-th
tile, so the instance lists, and every image and depth after them, are the same bit for bit; checked at face sizes
from 16² to 1024², a batch of probes and a level of detail's cut. (A frame past its budget, drawn again, is
tests/test_render_budgets.py's, which runs with the device's default.)"""
import numpy as np
import pytest

from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.vk import get_context
from test_raster_plane import _mixed
from test_raster_strips import _small_shell

ORIGIN = np.array([0.05, -0.1, 0.02])


def _frame(scene, per_splat: bool, monkeypatch, face: int = 0, probes=None, lod_k: float = 0.0):
    monkeypatch.setattr(R, "EMIT_PER_SPLAT", per_splat)
    r = R.SplatRenderer(scene, get_context(), lod=lod_k > 0)
    try:
        if probes is not None:
            res = r.render_probes(probes, 32, lod_k=lod_k)
            return res.frame.read_probes(), None, int(r.count.read(np.uint32, 4)[1])
        res = r.render(ViewBatch.cubemap(ORIGIN, face), depth=True, lod_k=lod_k)
        return np.stack(res.images), np.stack(res.depths), int(r.count.read(np.uint32, 4)[1])
    finally:
        r.close()


@pytest.mark.parametrize("face", [16, 64, 256, 1024])
def test_per_splat_emit_draws_the_per_slot_emits_frames(face, monkeypatch):
    scene = _mixed() if face == 1024 else _small_shell()
    slot = _frame(scene, False, monkeypatch, face)
    splat = _frame(scene, True, monkeypatch, face)
    assert slot[2] == splat[2] > 1000  # the same instances, all of them
    np.testing.assert_array_equal(slot[0], splat[0])
    np.testing.assert_array_equal(slot[1], splat[1])


def test_per_splat_emit_in_probe_batches_and_cuts(monkeypatch):
    scene = _small_shell()
    probes = np.array([[0.0, 0, 0], [0.4, -0.2, 0.1], [1.5, 0.5, -0.5]])
    for lod_k in (0.0, 2.0):
        slot = _frame(scene, False, monkeypatch, probes=probes, lod_k=lod_k)
        splat = _frame(scene, True, monkeypatch, probes=probes, lod_k=lod_k)
        assert slot[2] == splat[2]
        np.testing.assert_array_equal(slot[0], splat[0])


def test_per_splat_emit_on_cpu_devices_within_the_loop_limit():
    ctx = get_context()
    assert R.EMIT_PER_SPLAT is None
    assert R.emit_per_splat(ctx, 6 * 64 * 64) == bool(ctx.is_cpu)  # 1024² faces
    assert not R.emit_per_splat(ctx, R.EMIT_PER_SPLAT_MAX_TILES + 1)  # a splat's instances could pass 65,535 steps
