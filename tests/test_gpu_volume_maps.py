"""The light volume's maps made on the GPU (core/probe/gpu_volume_maps.py) against their numpy reference
(volume_bake.maps_from_cubes and the inside test's closeness) on a real render: the lamp room's probes in the open,
at a wall, outside the room (holes) and inside the lamp's ball, faces 8, 16 and 32. Float32 sums in another order:
within 1e-5 of each quantity's largest value (measured 2026-12-05: at most 2.1e-6 here, 2.8e-6 at other
places of the room)."""
import numpy as np
import pytest

from gs_ibl_addon.core.probe import gpu_volume_maps as gvm
from gs_ibl_addon.core.probe import volume_bake as vb
from gs_ibl_addon.core.probe import volume_rooms as rooms
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch

TOL = 1e-5
FAR, NEAR, HOLE = 20.0, 0.12, (0.1, 0.2, 0.3)
PROBES = np.array([(0.0, 0.0, 1.2), (-1.0, 0.5, 0.6), (1.4, -1.3, 0.2), rooms.LAMP, (0.0, 0.0, 4.0),
                   (0.7, -0.4, 2.3), (-1.45, 0.0, 1.0)])


@pytest.fixture(scope="module")
def renderer():
    with SplatRenderer(rooms.lamp_room()) as r:
        yield r


def _close(got, want, what):
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    err = np.abs(got - want).max() / max(np.abs(want).max(), 1e-30)
    assert err < TOL, f"{what}: {err:.2e} of the largest"


@pytest.mark.parametrize("face", [8, 16, 32])
def test_gpu_maps_equal_numpy(renderer, face):
    frame = renderer.render(ViewBatch.cubemaps(PROBES, face), depth=True).frame
    rgba = frame.read_probes()
    depth = frame.depth.read(np.float32, len(PROBES) * 6 * face * face).reshape(len(PROBES), 6, face, face)
    irr, mom, holes = vb.maps_from_cubes(rgba, depth, FAR, HOLE)
    close = vb.closeness(rgba, depth, NEAR)
    g_irr, g_mom, g_holes, g_close = gvm.volume_maps(frame, vb.irradiance_matrix(min(face, vb.IRR_FACE)),
                                                   vb.visibility_matrix(face), FAR, NEAR, HOLE)
    _close(g_irr, irr, "irradiance")
    _close(g_mom[..., 0], mom[..., 0], "mean distance")
    _close(g_mom[..., 1], mom[..., 1], "mean squared distance")
    assert np.abs(g_holes - holes).max() < TOL and np.abs(g_close - close).max() < TOL
    # the scene exercises what it should: a probe outside the room sees holes, the lamp's centre is inside it
    assert holes[4] > 0.3 and holes[0] < 1e-3 and close[3] > vb.INSIDE_FRACTION and close[0] == 0.0


def test_bake_probes_on_the_gpu_equals_the_numpy_path(renderer, monkeypatch):
    """bake_probes' two paths (GPU_MAPS) give the same maps and the same inside probes; 64^2 faces take numpy, and
    so does a CPU device unless told (lavapipe's maps are slower than numpy's)."""
    monkeypatch.setattr(vb, "GPU_MAPS", True)
    got = vb.bake_probes(renderer, PROBES, FAR, NEAR, 16, hole_colour=HOLE)
    assert not vb.bake_probes(renderer, PROBES[:1], FAR, NEAR, 64)["gpu_maps"]
    monkeypatch.setattr(vb, "GPU_MAPS", False)
    want = vb.bake_probes(renderer, PROBES, FAR, NEAR, 16, hole_colour=HOLE)
    assert got["gpu_maps"] and not want["gpu_maps"]
    _close(got["irradiance"], want["irradiance"], "irradiance")
    _close(got["moments"], want["moments"], "moments")
    assert np.abs(got["holes"] - want["holes"]).max() < TOL
    assert (got["inside"] == want["inside"]).all() and got["inside"][3] and got["inside"].sum() == 1
    monkeypatch.setattr(vb, "GPU_MAPS", None)
    assert vb.bake_probes(renderer, PROBES[:1], FAR, NEAR, 16)["gpu_maps"] == (not renderer.ctx.is_cpu)


def test_maps_queued_behind_a_render_drawn_again():
    """volume_maps given a render still in flight (render(wait=False), as bake_probes does on a GPU) is queued behind
    it; when that render outgrows its instance list and is drawn again, the maps are made again from the finished
    frame: the same as from a render waited for first."""
    scene = rooms.lamp_room()
    matrices = vb.irradiance_matrix(16), vb.visibility_matrix(16)
    with SplatRenderer(scene) as r:
        want = gvm.volume_maps(r.render(ViewBatch.cubemaps(PROBES, 16), depth=True).frame, *matrices, FAR, NEAR, HOLE)
    with SplatRenderer(scene) as r:
        r.capacity = 8  # as if every frame so far were tiny: this one is drawn again with room for its instances
        res = r.render(ViewBatch.cubemaps(PROBES, 16), depth=True, wait=False)
        got = gvm.volume_maps(res.frame, *matrices, FAR, NEAR, HOLE)
        assert res.instances > 8
    for g, w, what in zip(got, want, ("irradiance", "moments", "holes", "closeness")):
        assert np.array_equal(g, w), what
