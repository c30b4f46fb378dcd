"""core/render/mesh_depth.py: the meshes' depth a final render splits the splats at, against analytic answers and a
per-pixel ray cast, and the edge fill of the prototype (tests/real_blender/final_frame_probe.py)."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from gs_ibl_addon.core.render.mesh_depth import (camera_basis, fill_edges, frustum_from_projection, mesh_depth,
                                                 rasterise)
from gs_ibl_addon.core.render.views import View


def look(origin, rot_x_deg=90.0, rot_z_deg=0.0) -> np.ndarray:
    """A Blender camera's matrix_world: rotation_euler (rot_x, 0, rot_z) at ``origin`` ((90, 0, 0) looks along +Y)."""
    a, c = math.radians(rot_x_deg), math.radians(rot_z_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rz @ rx
    m[:3, 3] = origin
    return m


def pixel_rays(m, tan_x, tan_y, w, h, cx=0.0, cy=0.0):
    """Origin and (H, W, 3) directions (forward part 1) of the pixel centres, from the View convention."""
    b = camera_basis(m)
    v = View(-b[:3, 2], b[:3, 0], -b[:3, 1], tan_x, tan_y, w, h)
    s = ((np.arange(w) + 0.5) / w * 2 - 1) * tan_x + cx
    t = ((np.arange(h) + 0.5) / h * 2 - 1) * tan_y - cy
    tt, ss = np.meshgrid(t, s, indexing="ij")
    d = v.forward + ss[..., None] * v.right + tt[..., None] * v.down
    return b[:3, 3], d


def ray_cast(tris, origin, dirs):
    """Planar depth (forward part of each direction is 1) of the nearest triangle along each ray (Moller-Trumbore)."""
    best = np.full(dirs.shape[:2], np.inf)
    for a, b, c in tris:
        e1, e2 = b - a, c - a
        p = np.cross(dirs, e2)
        det = p @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = origin - a
            u = (p @ s) * inv
            q = np.cross(s, e1)
            v = (dirs @ q) * inv
            t = (q @ e2) * inv
        hit = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        best = np.where(hit & (t < best), t, best)
    return best


def quad(centre, u, v):
    c, u, v = (np.asarray(x, float) for x in (centre, u, v))
    p = [c - u - v, c + u - v, c + u + v, c - u + v]
    return np.array([[p[0], p[1], p[2]], [p[0], p[2], p[3]]])


def test_a_wall_facing_the_camera_is_at_its_distance():
    m = look((0, -5, 0))
    z = rasterise(quad((0, 2, 0), (1, 0, 0), (0, 0, 1)), m, 0.5, 0.375, 64, 48)
    # the wall at y = 2, seen from y = -5: 7 m along the view axis, spanning x in [-1, 1] of tan 0.5 * 7 = 3.5
    inside = np.isfinite(z)
    assert np.allclose(z[inside], 7.0, rtol=1e-6)
    cols = np.nonzero(inside.any(0))[0]
    # pixel centres with |s| * 3.5 <= 1: s = (i + 0.5) / 32 - 1
    want = [i for i in range(64) if abs(((i + 0.5) / 32 - 1) * 3.5) <= 1]
    assert list(cols) == want


def test_a_tilted_plane_and_random_triangles_match_a_ray_cast():
    m = look((0.3, -6, 0.4), 88.0, 4.0)
    tx, ty, w, h, cx, cy = 0.42, 0.3, 80, 57, 0.03, -0.02
    rng = np.random.default_rng(3)
    tris = [quad((0, 0, 0), (1.2, 0.9, 0), (0, 0, 0.7))]  # tilted: depth varies across it
    tris.append(rng.uniform(-1.5, 1.5, (40, 3, 3)) + [0, 1.0, 0])
    tris = np.concatenate(tris)
    z = rasterise(tris, m, tx, ty, w, h, cx, cy)
    o, d = pixel_rays(m, tx, ty, w, h, cx, cy)
    ref = ray_cast(tris, o, d)
    both = np.isfinite(z) & np.isfinite(ref)
    assert both.sum() > 0.3 * w * h
    np.testing.assert_allclose(z[both], ref[both], rtol=2e-5)
    # coverage differs only where a pixel centre lies on an edge (to rounding)
    assert (np.isfinite(z) != np.isfinite(ref)).sum() <= 2


def test_triangles_through_the_near_plane_are_clipped_not_dropped():
    m = look((0, 0, 0))
    # a floor under the camera from behind it (y = -3) to ahead (y = 10): crosses the near plane
    floor = quad((0, 3.5, -1), (4, 0, 0), (0, 6.5, 0))
    z = rasterise(floor, m, 0.6, 0.45, 40, 30, near=0.1)
    o, d = pixel_rays(m, 0.6, 0.45, 40, 30)
    ref = ray_cast(floor, o, d)
    ref[ref < 0.1] = np.inf
    assert np.isfinite(ref[-1]).all()  # the bottom rows see the floor near the camera
    both = np.isfinite(z) & np.isfinite(ref)
    np.testing.assert_allclose(z[both], ref[both], rtol=2e-5)
    assert (np.isfinite(z) != np.isfinite(ref)).sum() <= 2
    # wholly behind the camera: nothing
    assert not np.isfinite(rasterise(quad((0, -3, 0), (1, 0, 0), (0, 0, 1)), m, 0.6, 0.45, 40, 30)).any()


def test_far_plane_window_and_shift():
    m = look((0, -5, 0))
    wall = quad((0, 2, 0), (3, 0, 0), (0, 0, 3))
    assert not np.isfinite(rasterise(wall, m, 0.5, 0.4, 32, 24, far=6.9)).any()
    full = rasterise(np.concatenate([wall, quad((0.5, 0, 0.2), (0.3, 0.2, 0), (0, 0, 0.4))]), m, 0.5, 0.4, 50, 40,
                     cx=0.07, cy=0.05)
    win = rasterise(np.concatenate([wall, quad((0.5, 0, 0.2), (0.3, 0.2, 0), (0, 0, 0.4))]), m, 0.5, 0.4, 50, 40,
                    cx=0.07, cy=0.05, window=(11, 7, 37, 30))
    np.testing.assert_array_equal(win, full[7:30, 11:37])


def test_fill_edges_takes_the_nearest_covered_neighbour():
    z = np.full((5, 5), np.inf, np.float32)
    z[2, 2], z[2, 3] = 3.0, 2.0
    f = fill_edges(z)
    assert f[2, 1] == 3.0 and f[2, 4] == 2.0 and f[1, 2] == 3.0 and f[1, 3] == 2.0
    assert f[1, 1] == 3.0 and f[1, 4] == 2.0  # diagonals, where no 4-neighbour is covered
    assert f[1, 2] == 3.0 and not np.isfinite(f[0, 0])
    # mesh_depth of a window sees the mesh just outside it
    m = look((0, -5, 0))
    wall = quad((0, 2, 0), (1, 0, 0), (0, 0, 1))
    full = mesh_depth(wall, m, 0.5, 0.375, 64, 48)
    cols = np.nonzero(np.isfinite(rasterise(wall, m, 0.5, 0.375, 64, 48)).any(0))[0]
    x0 = int(cols[-1]) + 1  # the first column right of the wall: filled from it
    win = mesh_depth(wall, m, 0.5, 0.375, 64, 48, window=(x0, 0, 64, 48))
    np.testing.assert_array_equal(win, full[:, x0:])
    assert np.isfinite(win[:, 0]).any()


def test_camera_basis_takes_scale_out():
    m = look((1, 2, 3), 70.0, 30.0)
    np.testing.assert_allclose(camera_basis(m), m, atol=1e-12)
    scaled = m.copy()
    scaled[:3, :3] *= [2.0, 0.5, 3.0]
    np.testing.assert_allclose(camera_basis(scaled), m, atol=1e-12)


def test_frustum_from_blender_projection():
    n, f = 0.1, 100.0
    tx, ty, cx, cy = 0.4, 0.3, 0.05, -0.02
    l, r, b, t = n * (cx - tx), n * (cx + tx), n * (cy - ty), n * (cy + ty)
    p = np.array([[2 * n / (r - l), 0, (r + l) / (r - l), 0], [0, 2 * n / (t - b), (t + b) / (t - b), 0],
                  [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)], [0, 0, -1, 0]])
    np.testing.assert_allclose(frustum_from_projection(p), (tx, ty, cx, cy), atol=1e-12)
    ortho = np.diag([0.5, 0.5, -0.02, 1.0])
    with pytest.raises(ValueError, match="orthographic"):
        frustum_from_projection(ortho)


def test_many_triangles_are_fast():
    """A 20k-triangle sphere at 640x360 (the work is vectorised: no Python loop over triangles)."""
    lat, lon = np.meshgrid(np.linspace(0, np.pi, 101), np.linspace(0, 2 * np.pi, 101), indexing="ij")
    p = np.stack([np.sin(lat) * np.cos(lon), np.sin(lat) * np.sin(lon), np.cos(lat)], -1)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    m = look((0, -3, 0))
    t0 = time.perf_counter()
    z = rasterise(tris, m, 0.6, 0.3375, 640, 360)
    dt = time.perf_counter() - t0
    assert len(tris) == 20000 and dt < 5.0, dt
    # the sphere's nearest point is 2 m away, at the centre
    assert z[180, 320] == pytest.approx(2.0, rel=1e-3)
