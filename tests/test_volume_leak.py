"""Issue 37's leak test: a bright room and a dark room, one splat wall between (core/probe/volume_rooms.py). A sphere
in the dark room, lit by a volume whose nodes stand on both sides of the wall, against its exact irradiance (the
cosine integral of the dark room's known wall colours). Visibility is what keeps the bright room out."""
import numpy as np
import pytest

from gs_ibl_addon.core.probe import volume as vol
from gs_ibl_addon.core.probe import volume_rooms as vr
from gs_ibl_addon.core.probe.volume_bake import bake_volume
from gs_ibl_addon.core.render.renderer import SplatRenderer


@pytest.fixture(scope="module")
def leak():
    rooms = vr.two_rooms()
    with SplatRenderer(rooms.scene) as r:
        v = bake_volume(r, vr.LEAK_SPEC, face_size=16)
    pts, nrm = vr.sphere_points(300)
    return v, pts, nrm, rooms.exact(pts, nrm, 8000)


def test_nodes_stand_on_both_sides_of_the_wall(leak):
    v, pts, _, _ = leak
    x = v.spec.axis_points(0)
    assert (x < -vr.GAP / 2).any() and (x > vr.GAP / 2).any()
    cell = (x[:-1] < 0) & (x[1:] > 0)  # the cell spanning the wall holds part of the sphere
    lo, hi = x[:-1][cell][0], x[1:][cell][0]
    assert ((pts[:, 0] > lo) & (pts[:, 0] < hi)).mean() > 0.1
    assert v.report == []


def test_the_dark_rooms_sphere_is_within_3_percent(leak):
    """Measured (2026-12-05, 16^2 faces): the sphere's mean within 0.7% per channel, per-point error 0.9% mean, 5%
    at worst (a point 0.15 m from the wall, facing it). The packed atlas reads the same."""
    v, pts, nrm, exact = leak
    got = vol.sample(v, pts, nrm)
    assert np.all(np.abs(got.mean(0) / exact.mean(0) - 1) < 0.03)
    err = np.abs(got - exact) / exact
    assert err.mean() < 0.02 and err.max() < 0.1
    irr, vis = vol.pack_atlas(v)
    assert np.allclose(vol.sample_packed(irr, vis, v.spec, pts, nrm), got, rtol=1e-4)


def test_without_visibility_the_bright_room_leaks(leak):
    """The same volume with the Chebyshev test off: measured +29% red, +46% green, +61% blue on the sphere's mean,
    and points near the wall ~19x their light."""
    v, pts, nrm, exact = leak
    got = vol.sample(v, pts, nrm, visibility=False)
    assert np.all(got.mean(0) / exact.mean(0) > 1.2)
    assert (np.abs(got - exact) / exact).max() > 5
