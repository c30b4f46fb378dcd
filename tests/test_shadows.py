"""Shadows of meshes on the capture (core/render/shadows.py, issue 36 item 3), against answers known in closed form.

- The orthographic raster (mesh_depth.rasterise_ortho): a tilted triangle's depth is its plane's.
- One distant light straight down past a sphere: the shadow is the sphere's disc (lit outside it, dark inside).
- The environment's samples carry its integral and its irradiance on a surface (to sampling, 0.5 %).
- Contact darkening: a uniform sky over a point under a horizontal disc of radius a at height h loses
  a^2 / (a^2 + h^2) of its cosine-weighted light (the disc's view factor).
- The sun-like sky over a floor under a sphere: ours against a dense brute-force integral at points in the umbra,
  the penumbra and outside.
- The reduced-resolution path with its depth-aware upsampling against the full-resolution one; a render border
  against the crop of the full frame.
- A mesh's reflected light: under a disc of albedo rho the loss is its view factor times (1 - rho).
- Large meshes get fewer samples carrying the same light.
"""
from __future__ import annotations

import numpy as np

from gs_ibl_addon.core import cubemap, synthetic
from gs_ibl_addon.core.render import shadows
from gs_ibl_addon.core.render.mesh_depth import rasterise_ortho

SKY = synthetic.BrightPatch(direction=(0.55, 0.2, 0.81))


def uv_sphere(centre, r, nu=48, nv=24) -> np.ndarray:
    th = np.linspace(0, np.pi, nv + 1)[:, None]
    ph = np.linspace(0, 2 * np.pi, nu + 1)[None]
    p = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th) * np.ones_like(ph)], -1) * r
    p = p + np.asarray(centre, np.float64)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])


def disc(a: float, h: float, n: int = 96) -> np.ndarray:
    ang = np.linspace(0, 2 * np.pi, n + 1)
    rim = np.stack([a * np.cos(ang), a * np.sin(ang), np.full(n + 1, h)], 1)
    return np.stack([np.tile([0.0, 0.0, h], (n, 1)), rim[:-1], rim[1:]], 1)


def test_ortho_raster_depth_is_the_plane():
    tri = np.array([[[-1.0, -1.0, 0.2], [1.0, -1.0, 0.6], [0.0, 1.0, 1.0]]])
    basis = np.eye(3)  # right x, up y, forward z: depth = z
    z = rasterise_ortho(tri, basis, (-1.0, -1.0, 1.0, 1.0), 40, 40)
    u = -1 + (np.arange(40) + 0.5) / 20
    v = 1 - (np.arange(40) + 0.5) / 20
    uu, vv = np.meshgrid(u, v)
    n = np.cross(tri[0, 1] - tri[0, 0], tri[0, 2] - tri[0, 0])
    plane = tri[0, 0, 2] - (n[0] * (uu - tri[0, 0, 0]) + n[1] * (vv - tri[0, 0, 1])) / n[2]
    hit = np.isfinite(z)
    assert 300 < hit.sum() < 900  # about half the square
    np.testing.assert_allclose(z[hit], plane[hit], atol=1e-5)


def test_one_light_straight_down_gives_the_spheres_disc():
    tris = uv_sphere((0.0, 0.0, 1.0), 0.5)
    g = np.linspace(-1.5, 1.5, 121)
    x, y = np.meshgrid(g, g)
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    r = shadows.shadow_ratio(pts, up, tris, shadows.disc_samples([0, 0, 1], [1, 1, 1], 0.0))
    rad = np.hypot(pts[:, 0], pts[:, 1])
    assert r[rad < 0.47].max() == 0.0  # the mesh's polygon is inside the sphere: its disc a little less wide
    assert r[rad > 0.53].min() > 1 - 1e-9


def _texel_omega(h: int) -> np.ndarray:
    return (2 * np.pi / (2 * h)) * (np.pi / h) * np.sin((np.arange(h) + 0.5) / h * np.pi)[:, None, None]


def test_environment_samples_carry_its_integral_and_irradiance():
    h = 256
    dirs = cubemap.latlong_directions(2 * h, h)
    env = SKY(dirs)
    s = shadows.environment_samples(env)
    assert s.count == shadows.BRIGHT_SAMPLES + shadows.SKY_SAMPLES
    om = _texel_omega(h)
    np.testing.assert_allclose(s.weights.sum(0), (env * om).sum((0, 1)), rtol=1e-3)
    for n in ([0, 0, 1.0], [1.0, 0, 0], [0, -0.6, 0.8]):
        cos = np.maximum(s.directions @ n, 0)
        exact = (env * om * np.maximum(dirs @ n, 0)[..., None]).sum((0, 1))
        np.testing.assert_allclose((s.weights * cos[:, None]).sum(0), exact, rtol=5e-3)
    sun = SKY.in_disc(s.directions)
    assert sun.sum() >= shadows.BRIGHT_SAMPLES  # the bright part's samples all lie on the sun's disc


def test_contact_darkening_is_the_discs_view_factor():
    env = np.ones((128, 256, 3))
    s = shadows.light_samples(env)
    for a, h in ((1.0, 1.0), (0.5, 1.0), (1.0, 0.3)):
        r = shadows.shadow_ratio(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), disc(a, h), s)
        exact = 1 - a * a / (a * a + h * h)
        assert abs(r[0, 0] - exact) < 0.03, (a, h, r[0, 0], exact)


def test_sun_and_sky_under_a_sphere_against_brute_force():
    tris = uv_sphere((0.0, 0.0, 0.5), 0.4)
    h = 256
    dirs = cubemap.latlong_directions(2 * h, h)
    env = SKY(dirs)
    s = shadows.light_samples(env)
    pts = np.array([[0, 0, 0.0], [-0.34, -0.12, 0], [-0.6, -0.2, 0], [0.5, 0, 0], [1, 1, 0], [3, 0, 0]])
    ours = 1 - shadows.shadow_ratio(pts, np.tile([0, 0, 1.0], (len(pts), 1)), tris, s)[:, 1]
    w = env[..., 1] * _texel_omega(h)[..., 0] * np.maximum(dirs[..., 2], 0)
    for p, d in zip(pts, ours):
        v = np.array([0, 0, 0.5]) - p
        blocked = dirs @ (v / np.linalg.norm(v)) > np.cos(np.arcsin(0.4 / np.linalg.norm(v)))
        exact = (w * blocked).sum() / w.sum()
        assert abs(d - exact) < 0.02 + 0.05 * exact, (p, d, exact)


def test_reduced_resolution_matches_full():
    """A camera over a floor (depth from the plane) with a sphere: every 3rd pixel upsampled against every pixel."""
    w, h, tan = 180, 120, 0.5
    cam = np.eye(4)
    cam[:3, :3] = [[1, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]]  # looking down at 53 degrees: -Z = (0, 0.8, -0.6)
    cam[:3, 3] = [0, -3.0, 2.5]
    rays, o = shadows.camera_rays(cam, tan, tan * h / w, w, h)
    depth = (-o[2] / rays[..., 2]).astype(np.float32)  # planar depth of z = 0
    tris = uv_sphere((0.0, 0.3, 0.5), 0.4)
    s = shadows.light_samples(SKY(cubemap.latlong_directions(256, 128)))
    alpha = np.ones((h, w), np.float32)
    full = shadows.frame_ratio(depth, alpha, tris, s, cam, tan, tan * h / w, w, h, max_side=1000)
    low = shadows.frame_ratio(depth, alpha, tris, s, cam, tan, tan * h / w, w, h, max_side=60)
    assert full.min() < 0.3  # there is a shadow
    err = np.abs(low - full)[..., 1]
    assert err.mean() < 0.01 and np.percentile(err, 99) < 0.08, (err.mean(), np.percentile(err, 99))


def test_apply_darkens_the_surface_layer_only():
    front = np.full((2, 2, 4), 0.5, np.float32)
    behind = np.full((2, 2, 4), 0.25, np.float32)
    ratio = np.full((2, 2, 3), 0.5, np.float32)
    no_mesh = np.array([[True, False], [True, False]])
    f, b = shadows.apply(front, behind, ratio, no_mesh, strength=0.5)
    np.testing.assert_allclose(f[:, 0, :3], 0.375)  # 1 - 0.5 (1 - 0.5) = 0.75
    np.testing.assert_allclose(f[:, 1, :3], 0.5)
    np.testing.assert_allclose(b[:, 1, :3], 0.1875)
    np.testing.assert_allclose(b[:, 0, :3], 0.25)
    np.testing.assert_allclose(f[..., 3], 0.5)  # coverage kept


def test_a_meshs_reflected_light_fills_its_shadow():
    """Uniform sky (radiance 1) over a point under a horizontal disc of albedo rho: the disc's underside sees the
    lower sky (irradiance pi), so it shines rho back where it blocks 1: the loss is F (1 - rho), F its view
    factor. The samples' solid angles add up to the sphere's."""
    s = shadows.light_samples(np.ones((128, 256, 3)))
    np.testing.assert_allclose(s.solid_angles.sum(), 4 * np.pi, rtol=1e-3)
    sun = shadows.light_samples(SKY(cubemap.latlong_directions(512, 256)))
    np.testing.assert_allclose(sun.solid_angles.sum(), 4 * np.pi, rtol=0.05)
    a, h = 1.0, 1.0
    f = a * a / (a * a + h * h)
    for rho in (0.0, 0.5, 0.8):
        r = shadows.shadow_ratio(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), disc(a, h), s, albedo=(rho,) * 3)
        assert abs(r[0, 0] - (1 - f * (1 - rho))) < 0.03, (rho, r[0, 0])


def test_large_meshes_get_fewer_samples_with_the_same_light():
    assert shadows.sample_scale(2000) == 1.0
    assert shadows.sample_scale(10_000_000) == 0.125
    env = SKY(cubemap.latlong_directions(256, 128))
    full, few = shadows.light_samples(env), shadows.light_samples(env, scale=0.25)
    assert few.count == 8 + 24
    np.testing.assert_allclose(few.weights.sum(0), full.weights.sum(0), rtol=1e-3)


def test_a_render_border_is_the_crop_of_the_full_frame():
    w, h, tan = 90, 60, 0.5
    cam = np.eye(4)
    cam[:3, :3] = [[1, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]]
    cam[:3, 3] = [0, -3.0, 2.5]
    rays, o = shadows.camera_rays(cam, tan, tan * h / w, w, h, cx=0.05, cy=-0.03)
    depth = (-o[2] / rays[..., 2]).astype(np.float32)
    tris = uv_sphere((0.0, 0.3, 0.5), 0.4, 24, 12)
    s = shadows.light_samples(SKY(cubemap.latlong_directions(256, 128)))
    args = (tris, s, cam, tan, tan * h / w, w, h, 0.05, -0.03)
    full = shadows.frame_ratio(depth, np.ones((h, w)), *args)
    x0, y0, x1, y1 = 20, 10, 70, 45
    part = shadows.frame_ratio(depth[y0:y1, x0:x1], np.ones((y1 - y0, x1 - x0)), *args, window=(x0, y0, x1, y1))
    assert full.min() < 0.5
    np.testing.assert_allclose(part, full[y0:y1, x0:x1], atol=0.02)
