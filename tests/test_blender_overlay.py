"""Viewport overlay logic: viewport matrices -> our renderer's camera -> the splat image the draw handler shows.

The bpy module cannot draw (GPU drawing raises in background mode), so what is tested is everything up to the
texture: the matrix conversion (against ViewBatch.pinhole and against Blender's own camera matrices), the image
(against the numpy reference renderer), re-rendering only on a view change, and the handler's object cache.
"""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from gs_ibl_addon.blender.viewport.overlay_math import (SplatOverlay, ViewMotion, linear_to_srgb, look_at_view_matrix,
                                               overlay_view, perspective_matrix, to_display, view_key, window_depth)
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene
from gs_ibl_addon.core.synthetic import random_scene

TOL = 2e-4  # GPU float32 against the float64 reference (tests/test_renderer.py)
POS, TARGET = (2.5, -3.0, 1.6), (0.0, 0.2, 0.1)


def small_scene():
    return random_scene(300, seed=4, sh_degree=1, extent=1.0)


def _same_view(a, b, atol=1e-9):
    for f in ("forward", "right", "down"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), atol=atol)
    assert (a.width, a.height) == (b.width, b.height)
    assert a.tan_x == pytest.approx(b.tan_x, abs=atol) and a.tan_y == pytest.approx(b.tan_y, abs=atol)


def test_matrices_give_the_pinhole_camera_and_its_image():
    w, h = 48, 32
    ov = overlay_view(look_at_view_matrix(POS, TARGET), perspective_matrix(55.0, w, h), w, h)
    ref = ViewBatch.pinhole(POS, TARGET, 55.0, w, h)
    np.testing.assert_allclose(ov.batch.origin, ref.origin, atol=1e-9)
    _same_view(ov.batch.views[0], ref.views[0])
    assert ov.batch.pixel_angle == pytest.approx(ref.pixel_angle)
    np.testing.assert_allclose(ov.ndc_rect, (-1, -1, 1, 1), atol=1e-9)
    r = SplatRenderer(small_scene())
    a, b = r.render(ov.batch).images[0], r.render(ref).images[0]
    assert a[..., 3].max() > 0.5
    np.testing.assert_array_equal(a, b)


def test_resolution_scale_and_off_centre_projection_rays():
    """A shifted (off-axis) projection at half resolution: every region pixel's ray, found through the quad's NDC
    rectangle in the rendered image, is the ray Blender's matrices give that pixel."""
    w, h, scale = 64, 40, 0.5
    v = look_at_view_matrix(POS, TARGET)
    p = perspective_matrix(50.0, w, h, shift_x=0.12, shift_y=-0.07)
    ov = overlay_view(v, p, w, h, scale)
    view = ov.batch.views[0]
    x0, y0, x1, y1 = ov.ndc_rect
    assert x0 < -1 and x1 == pytest.approx(1, abs=0.05) and y1 > 1  # the symmetric frustum covers the region
    # pixel size is kept: the region's half-resolution pixel equals a rendered pixel
    assert (x1 - x0) / view.width == pytest.approx(2 / (w * scale), rel=0.02)
    inv = np.linalg.inv(p @ v)
    rng = np.random.default_rng(0)
    ndc = rng.uniform(-1, 1, (200, 2))
    far = inv @ np.c_[ndc, np.ones(200), np.ones(200)].T
    near = inv @ np.c_[ndc, -np.ones(200), np.ones(200)].T
    want = (far[:3] / far[3] - near[:3] / near[3]).T
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    s = (ndc[:, 0] - x0) / (x1 - x0) * 2 - 1  # image coordinates in (-1, 1), t pointing down
    t = 1 - (ndc[:, 1] - y0) / (y1 - y0) * 2
    got = view.forward + s[:, None] * view.tan_x * view.right + t[:, None] * view.tan_y * view.down
    got /= np.linalg.norm(got, axis=1, keepdims=True)
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_orthographic_view_is_approximated_within_a_percent():
    half = 2.0
    v = look_at_view_matrix(POS, TARGET)
    p = np.identity(4)
    p[0, 0], p[1, 1], p[2, 2], p[2, 3] = 1 / half, 1.5 / half, -0.02, 0.0
    ov = overlay_view(v, p, 60, 40)
    assert not ov.perspective
    pts = np.random.default_rng(1).uniform(-1, 1, (50, 3))
    clip = p @ v @ np.c_[pts, np.ones(50)].T
    want = clip[:2].T / clip[3][:, None]
    view, o = ov.batch.views[0], ov.batch.origin
    rel = pts - o
    z = rel @ view.forward
    s, t = rel @ view.right / (z * view.tan_x), rel @ view.down / (z * view.tan_y)
    x0, y0, x1, y1 = ov.ndc_rect
    got = np.c_[x0 + (s + 1) / 2 * (x1 - x0), y1 - (t + 1) / 2 * (y1 - y0)]
    np.testing.assert_allclose(got, want, atol=0.02)  # NDC units: 1% of the view


def test_overlay_image_matches_reference_and_rerenders_only_on_change():
    scene = small_scene()
    ovl = SplatOverlay(scene)
    v, p = look_at_view_matrix(POS, TARGET), perspective_matrix(60.0, 40, 30)
    img = ovl.image(v, p, 40, 30)
    assert ovl.renders == 1 and img.rgba.shape == (30, 40, 4)
    cover = img.rgba[..., 3]
    assert (cover > 0.01).mean() > 0.2 and cover.max() > 0.5  # non-empty
    ref = render_reference(scene, img.view.batch)[0]
    err = np.abs(img.rgba - ref).max()
    assert err < TOL, err
    assert ovl.image(v.copy(), p.copy(), 40, 30) is img and ovl.renders == 1  # same view: cached
    ovl.image(v, p, 40, 30, slot="another region")
    assert ovl.renders == 2  # each viewport region keeps its own image
    moved = look_at_view_matrix((2.4, -3.0, 1.6), TARGET)
    assert ovl.image(moved, p, 40, 30) is not img and ovl.renders == 3
    ovl.image(moved, p, 40, 30, scale=0.5)
    assert ovl.renders == 4
    ovl.close()


def _ortho(half: float = 2.0) -> np.ndarray:
    p = np.identity(4)
    p[0, 0], p[1, 1], p[2, 2], p[2, 3] = 1 / half, 1.5 / half, -2 / 30, -32 / 30  # near 1, far 31
    return p


@pytest.mark.parametrize("projection", ["perspective", "shifted", "orthographic"])
def test_window_depth_is_the_depth_buffer_value_of_the_point(projection):
    """A world point at distance d along the render camera's axis gets the window depth the viewport's depth buffer
    holds for it: (ndc_z + 1) / 2 of (window @ view @ point), for perspective, shifted and orthographic views."""
    w, h = 64, 40
    v = look_at_view_matrix(POS, TARGET)
    p = {"perspective": perspective_matrix(50.0, w, h, near=0.1, far=40.0),
         "shifted": perspective_matrix(50.0, w, h, near=0.1, far=40.0, shift_x=0.1, shift_y=-0.05),
         "orthographic": _ortho()}[projection]
    ov = overlay_view(v, p, w, h)
    pts = np.random.default_rng(2).uniform(-1.5, 1.5, (300, 3))
    clip = p @ v @ np.c_[pts, np.ones(len(pts))].T
    want = (clip[2] / clip[3] + 1) / 2
    fwd = ov.batch.views[0].forward
    dist = (pts - ov.batch.origin) @ fwd  # what the renderer's depth image holds for a splat there
    got = window_depth(dist, ov)
    np.testing.assert_allclose(got, want, atol=2e-6)
    assert window_depth(np.zeros(3), ov).tolist() == [1.0, 1.0, 1.0]  # nothing seen: the far plane
    assert np.all(window_depth(dist, ov, pull=0.02) < got)  # pulled toward the eye


def test_rendered_depth_gives_window_depth_of_the_surface():
    """The renderer's depth image through window_depth: a wall of opaque splats facing the view lands at the
    window depth of that plane."""
    n_side, z_wall = 24, 3.0
    g = (np.arange(n_side) - (n_side - 1) / 2) * 0.25
    x, y = np.meshgrid(g, g)
    n = x.size
    pos = np.c_[x.ravel(), y.ravel(), np.full(n, -z_wall)].astype(np.float32)  # the plane z = -3 of view space
    flat = np.array([0.3, 0.3, 0.002], np.float32)
    scene = SplatScene(pos, np.tile(flat, (n, 1)), np.tile(np.array([1, 0, 0, 0], np.float32), (n, 1)),
                       np.full(n, 0.99, np.float32), np.zeros((n, 1, 3), np.float32))
    w, h = 40, 30
    v, p = np.identity(4), perspective_matrix(40.0, w, h, near=0.5, far=20.0)
    ovl = SplatOverlay(scene)
    img = ovl.image(v, p, w, h)
    covered = img.rgba[..., 3] > 0.99
    assert covered.mean() > 0.9
    np.testing.assert_allclose(img.depth[covered], z_wall, rtol=2e-3)  # the splats' thickness (2 mm) apart
    want = (((p[2, 2] * -z_wall + p[2, 3]) / z_wall) + 1) / 2
    np.testing.assert_allclose(img.window_depth()[covered], want, atol=2e-4)
    ovl.close()


def test_view_motion_coarse_while_moving_full_once_still():
    m, full = ViewMotion(settle_s=0.25, moving_scale=0.25), 0.5
    a, b, c = (view_key(look_at_view_matrix(e, TARGET), perspective_matrix(50, 40, 30), 40, 30)
               for e in (POS, (2.4, -3.0, 1.6), (2.3, -3.0, 1.6)))
    assert m.scale("r", a, 10.0, full) == full and m.refine_in(10.0) is None  # first sight: full at once
    assert m.scale("r", a, 10.5, full) == full  # still
    assert m.scale("r", b, 10.6, full) == 0.25  # moved: coarse
    assert m.refine_in(10.6) == pytest.approx(0.25)
    assert m.scale("r", c, 10.7, full) == 0.25  # moving on
    assert m.refine_in(10.8) == pytest.approx(0.15)
    assert m.scale("r", c, 10.8, full) == 0.25  # unchanged, not yet settled
    assert m.scale("r", c, 10.96, full) == full and m.refine_in(10.96) is None  # settled: full, nothing to refine
    assert m.scale("other region", b, 11.0, full) == full  # regions are independent
    assert m.scale("r", a, 11.0, 0.2) == 0.2  # a Resolution below the moving scale is never raised


def test_to_display_premultiplied_srgb():
    img = np.array([[[0.25, 0.5, 4.0, 0.5], [0.0, 0.0, 0.0, 0.0]]], np.float32)
    out = to_display(img)
    # colour 0.5, 1.0, 8 -> clipped to 1 -> premultiplied by 0.5 -> sRGB-encoded; alpha kept
    np.testing.assert_allclose(out[0, 0], [*linear_to_srgb(np.array([0.25, 0.5, 0.5])), 0.5], atol=1e-6)
    np.testing.assert_array_equal(out[0, 1], 0)
    np.testing.assert_allclose(linear_to_srgb(np.array([0.0, 0.0031308, 0.5, 1.0])), [0, 0.04045, 0.7353569, 1.0],
                               atol=1e-5)
    np.testing.assert_allclose(to_display(img, exposure=-3.0)[0, 0, 2], linear_to_srgb(np.array(0.5)), atol=1e-6)


# ---------------------------------------------------------------------------------------------- inside Blender

bpy_only = pytest.mark.skipif(__import__("importlib").util.find_spec("bpy") is None, reason="bpy not installed")


@bpy_only
def test_blender_camera_matrices_give_the_same_image(blender):
    """Blender's own matrices (camera.calc_matrix_camera, the inverse of matrix_world), as the viewport's are in
    camera view, give the camera ViewBatch.pinhole describes."""
    bpy = blender
    w, h = 48, 36
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = w, h
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    cam.location = POS
    cam.rotation_euler = (math.radians(70), 0.0, math.radians(35))
    bpy.context.view_layer.update()
    window = np.array(cam.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=w, y=h))
    view = np.array(cam.matrix_world.inverted())
    ov = overlay_view(view, window, w, h)
    m = np.array(cam.matrix_world)
    ref = ViewBatch.pinhole(m[:3, 3], m[:3, 3] - m[:3, 2], math.degrees(cam.data.angle_x), w, h,
                            up=m[:3, 1])
    _same_view(ov.batch.views[0], ref.views[0], atol=1e-6)
    r = SplatRenderer(small_scene())
    # The two views agree to 1e-6, and the plane forms (tests/test_raster_plane.py) round differently for each: their
    # images may part by float32 rounding, which that file bounds at 5e-5.
    np.testing.assert_allclose(r.render(ov.batch).images[0], r.render(ref).images[0], atol=5e-5)


@bpy_only
def test_handler_image_follows_the_splat_object(blender):
    """splat_image (what draw_callback draws) renders the object in world space, caches its upload, and uploads
    again when the object moves; the overlay toggle hides the point proxy."""
    bpy = blender
    from gs_ibl_addon.blender.viewport import overlay_images
    from gs_ibl_addon.blender.splats.object import create_splat_object, scene_from_object
    from mathutils import Matrix
    obj = create_splat_object(bpy.context, small_scene(), "S")
    rv3d = SimpleNamespace(view_matrix=Matrix(look_at_view_matrix(POS, TARGET).tolist()),
                           window_matrix=Matrix(perspective_matrix(60.0, 40, 30).tolist()))
    img = overlay_images.splat_image(obj, rv3d, 40, 30, 1.0)
    ref = render_reference(scene_from_object(obj), img.view.batch)[0]
    assert np.abs(img.rgba - ref).max() < TOL and img.rgba[..., 3].max() > 0.5
    first = overlay_images.overlay_for(obj)
    assert overlay_images.overlay_for(obj) is first
    obj.location = (0.5, 0.0, 0.0)
    bpy.context.view_layer.update()
    img2 = overlay_images.splat_image(obj, rv3d, 40, 30, 1.0)
    assert overlay_images.overlay_for(obj) is not first
    assert np.abs(img2.rgba - render_reference(scene_from_object(obj), img2.view.batch)[0]).max() < TOL
    settings = bpy.context.scene.gs_ibl_overlay
    settings.show = False
    assert not overlay_images._overlays  # images freed when off


@bpy_only
def test_display_settings_never_upload_again_and_helpers_hide(blender):
    """Show Splats, Resolution and Exposure are display-only: however often they change (with the depsgraph
    evaluated in between, as in the GUI), the splats are not read or uploaded again; while the overlay shows, the
    point proxy draws nothing (fraction 0), and its fraction comes back after. An edit of the mesh still uploads."""
    bpy = blender
    from gs_ibl_addon.blender.viewport import overlay, overlay_images
    from gs_ibl_addon.blender.splats import cache as splat_cache
    from gs_ibl_addon.blender.common.compat import get_modifier_input, modifier_input_identifiers
    from gs_ibl_addon.blender.splats.object import PROXY_MODIFIER, create_splat_object
    from mathutils import Matrix
    obj = create_splat_object(bpy.context, small_scene(), "S")
    mod = obj.modifiers[PROXY_MODIFIER]
    frac = modifier_input_identifiers(mod.node_group)["Fraction"]
    f0 = get_modifier_input(mod, frac)
    rv3d = SimpleNamespace(view_matrix=Matrix(look_at_view_matrix(POS, TARGET).tolist()),
                           window_matrix=Matrix(perspective_matrix(60.0, 40, 30).tolist()))
    bpy.context.view_layer.update()
    overlay_images.splat_image(obj, rv3d, 40, 30, 1.0)
    n0 = splat_cache.uploads
    settings = bpy.context.scene.gs_ibl_overlay
    for step in range(3):
        settings.show = True
        bpy.context.view_layer.update()
        assert get_modifier_input(mod, frac) == 0.0 and obj.modifiers[PROXY_MODIFIER].show_viewport
        settings.exposure = 1.5 - step
        settings.resolution_scale = 0.3 + 0.2 * step
        bpy.context.view_layer.update()
        overlay_images.splat_image(obj, rv3d, 40, 30, settings.resolution_scale)
        settings.show = False
        bpy.context.view_layer.update()
        assert get_modifier_input(mod, frac) == pytest.approx(f0) and overlay.HIDDEN_KEY not in obj.keys()
        overlay_images.splat_image(obj, rv3d, 40, 30, 1.0)
    assert splat_cache.uploads == n0
    obj.data.vertices[0].co.x += 0.25  # a real edit
    obj.data.update()
    bpy.context.view_layer.update()
    overlay_images.splat_image(obj, rv3d, 40, 30, 1.0)
    assert splat_cache.uploads == n0 + 1


@bpy_only
def test_panel_wraps_long_lines(blender):
    from gs_ibl_addon.blender.ui.panel import wrapped_lines
    report = ("Baked 21,939 splats, 512x512 faces\nexact; face size by irradiance change (64: 7.45%, 128: 3.32%, "
              "256: 1.50%, 512: 0.61%) converged")
    lines = wrapped_lines(report, 30)
    assert all(len(x) <= 30 for x in lines) and len(lines) >= 4
    assert " ".join(lines).split() == report.split()  # nothing lost, words kept whole


# ------------------------------------------------------------------------- the composite and what the mouse hits

from gs_ibl_addon.blender.viewport import overlay_math as om  # noqa: E402


def _bytes(rgb_lin, alpha) -> np.ndarray:
    """Overlay-layer pixels as Blender stores them: sRGB-encoded premultiplied colour, linear alpha, 8 bits."""
    out = np.empty(np.shape(alpha) + (4,), np.uint8)
    out[..., :3] = np.round(linear_to_srgb(np.asarray(rgb_lin, np.float64)) * 255)
    out[..., 3] = np.round(np.asarray(alpha, np.float64) * 255)
    return out


def test_composite_keeps_mesh_edges_and_lines():
    """overlay_math.composite, pixel by pixel on a 1 x 9 strip, against the compositing written out by hand: the
    splats over the background; behind a mesh (kept); the part of a mesh edge pixel the mesh does not cover, with
    and without its own depth (the nearest neighbour's then); a mesh edge behind the splats; a line without depth
    (covered), one in the cursor disc (on top), one that writes depth in front of the splats (kept)."""
    bg = np.array([0.05, 0.05, 0.05])
    s_col, s_a, s_d = np.array([0.3, 0.2, 0.1]), 0.8, 0.9  # the splat layer: premultiplied colour, coverage, depth
    cov = np.array([0.0, 1.0, 0.4, 0.4, 0.4, 0.0, 0.0, 0.0, 0.0])
    depth = np.array([1.0, 0.5, 0.5, 1.0, 0.95, 1.0, 1.0, 1.0, 0.5])
    line_a = np.array([0, 0, 0, 0, 0, 0.6, 0.6, 0, 0.6])
    line_c = np.array([0.0, 0.0, 0.8])  # premultiplied blue
    o_rgb = (1 - cov)[:, None] * bg
    o_rgb = np.where(line_a[:, None] > 0, line_c * line_a[:, None] + (1 - line_a[:, None]) * o_rgb, o_rgb)
    o8 = _bytes(o_rgb[None], line_a[None])
    o_lin, o_alpha = om.decode_overlay(o8)
    n = len(cov)
    layer = (np.tile(s_col, (1, n, 1)), np.full((1, n), s_a), np.full((1, n), s_d))
    out, written = om.composite(o8, depth[None], [layer], bg, discs=[(6.5, 0.5, 0.6)])
    assert written.all()
    over = s_col + (1 - s_a) * bg  # the splats over the background
    c = 1 - o_lin[0, :, 2] / bg[2]  # the coverage as the layer's bytes tell it
    want = [
        (over, s_a),  # background
        (np.zeros(3), 0.0),  # mesh in front, fully covering: nothing over the render
        ((1 - c[2]) * over, 0.0),  # edge in front, own depth: the splats replace the part it does not cover
        ((1 - c[3]) * over, 0.0),  # edge without own depth: its neighbour's (pixel 2, 0.5) says in front
        (s_col + (1 - s_a) * (1 - c[4]) * bg, s_a),  # edge behind the splats: they cover it
        (s_col + (1 - s_a) * o_lin[0, 5], s_a + (1 - s_a) * o_alpha[0, 5]),  # a line without depth: covered
        (o_lin[0, 6] + (1 - o_alpha[0, 6]) * (s_col - s_a * bg), o_alpha[0, 6] + (1 - o_alpha[0, 6]) * s_a),  # disc
        (over, s_a),  # background
        (o_lin[0, 8], o_alpha[0, 8]),  # a line writing depth in front of the splats: kept
    ]
    for i, (rgb, a) in enumerate(want):
        np.testing.assert_allclose(out[0, i, :3], rgb, atol=1e-9, err_msg=f"pixel {i}")
        assert out[0, i, 3] == pytest.approx(a, abs=1e-9), f"pixel {i}"
    assert 0.35 < c[2] < 0.45  # the edge's coverage comes back from the background bytes within an 8-bit step


def test_composite_orders_layers_per_pixel_and_ignores_the_grid():
    """Two splat layers composite nearest first whatever their order; a line pixel whose depth is a point of the
    floor plane (the grid, which writes its depth) hides no splats, a line off the plane does."""
    w, h = 6, 4
    view = look_at_view_matrix((0.0, -4.0, 3.0), (0.0, 0.0, 0.0))
    win = perspective_matrix(60.0, w, h, 0.1, 50.0)
    # window depth of the floor (z = 0) at every pixel centre, and of a point 0.5 above it
    inv = np.linalg.inv(win @ view)
    eye = np.linalg.inv(view)[:3, 3]
    floor, above = np.ones((h, w)), np.ones((h, w))
    for r in range(h):
        for cc in range(w):
            far = inv @ np.array([(cc + 0.5) / w * 2 - 1, 1 - (r + 0.5) / h * 2, 1.0, 1.0])
            ray = far[:3] / far[3] - eye
            for target, z in ((floor, 0.0), (above, 0.5)):
                p = eye + ray * ((z - eye[2]) / ray[2])
                clip = win @ view @ np.array([*p, 1.0])
                target[r, cc] = 0.5 * clip[2] / clip[3] + 0.5
    line = np.full((h, w), 0.7)
    o8 = _bytes(np.full((h, w, 3), 0.2), line)
    mid = 0.5 * (floor + above)  # both layers between the two planes (z = 0.5 is the nearer)
    near = (np.full((h, w, 3), [0.5, 0.0, 0.0]), np.full((h, w), 0.5), mid - 0.1 * (floor - above))
    far_ = (np.full((h, w, 3), [0.0, 0.0, 0.4]), np.full((h, w), 0.5), mid + 0.1 * (floor - above))
    for grid_depth, hidden in ((floor, False), (above, True)):
        for layers in ([near, far_], [far_, near]):
            out, _ = om.composite(o8, grid_depth, layers, np.zeros(3), grid=(view, win, (0, 0, 1)))
            if hidden:  # a line at z = 0.5, nearer than both layers: drawn as is
                np.testing.assert_allclose(out[..., :3], om.decode_overlay(o8)[0], atol=1e-9)
            else:  # the grid: both layers over it, the nearer (red) first
                np.testing.assert_allclose(out[0, 0, :3], [0.5, 0, 0] + 0.5 * np.array([0, 0, 0.4]) +
                                           0.25 * om.decode_overlay(o8)[0][0, 0], atol=1e-9)
    assert om.grid_pixels(floor, np.ones((h, w), bool), view, win, (0, 0, 1)).all()
    assert not om.grid_pixels(above, np.ones((h, w), bool), view, win, (0, 0, 1)).any()


def test_viewport_background_matches_blender_gradients():
    hi, lo = np.array([0.2, 0.3, 0.4]), np.array([0.01, 0.02, 0.03])
    np.testing.assert_allclose(om.viewport_background("SINGLE_COLOR", hi, lo, 3, 2), np.broadcast_to(hi, (2, 3, 3)))
    lin = om.viewport_background("LINEAR", hi, lo, 1, 1000)
    np.testing.assert_allclose(lin[0, 0], hi, rtol=0.01)  # top row: high
    np.testing.assert_allclose(lin[-1, 0], lo, rtol=0.05)  # bottom row: low
    mid = np.power(0.5 * (hi ** (1 / 2.2) + lo ** (1 / 2.2)), 2.2)
    np.testing.assert_allclose(lin[500, 0], mid, rtol=0.01)  # interpolated in a 1/2.2 power space
    rad = om.viewport_background("RADIAL", hi, lo, 101, 101)
    np.testing.assert_allclose(rad[50, 50], hi, rtol=1e-3)  # centre high, corners low
    np.testing.assert_allclose(rad[0, 0], lo, rtol=0.1)


@pytest.mark.parametrize("projection", ["perspective", "shifted", "orthographic"])
def test_mouse_ray_is_the_pixel_ray_of_the_viewport_matrices(projection):
    """mouse_ray(x, y) goes through the NDC point (2x/w - 1, 2y/h - 1) at every depth, as Blender's operators
    take event.mval (no half-pixel offset)."""
    w, h = 64, 40
    v = look_at_view_matrix(POS, TARGET)
    p = {"perspective": perspective_matrix(50.0, w, h, near=0.1, far=40.0),
         "shifted": perspective_matrix(50.0, w, h, near=0.1, far=40.0, shift_x=0.1, shift_y=-0.05),
         "orthographic": _ortho()}[projection]
    for x, y in ((0, 0), (17, 33), (63, 5)):
        o, d = om.mouse_ray(v, p, w, h, x, y)
        assert np.linalg.norm(d) == pytest.approx(1.0)
        for t in (0.5, 2.0, 7.0):
            clip = p @ v @ np.array([*(o + t * d), 1.0])
            np.testing.assert_allclose(clip[:2] / clip[3], [2 * x / w - 1, 2 * y / h - 1], atol=1e-9)


def test_splat_hit_lands_on_the_sample_floor():
    """The splats under a pixel of the overlay's image (its depth, bilinear between the pixels with splats) land on
    the sample room's floor (z = 0, thin splats) within 2 cm, the tolerance of the GUI check's Shift+right-click,
    at full and at half resolution; an uncovered pixel hits nothing."""
    from gs_ibl_addon.core.formats import read_scene
    scene = read_scene(str(Path(__file__).resolve().parents[1] / "samples" / "room.ply"))
    w, h = 400, 250
    v = look_at_view_matrix((0.6, -0.6, 1.7), (-0.8, 1.2, 0.0))
    p = perspective_matrix(70.0, w, h, 0.05, 100.0)
    ovl = SplatOverlay(scene)
    try:
        for scale in (1.0, 0.5):
            img = ovl.image(v, p, w, h, scale)
            errors = []
            for x, y in ((200, 125), (175, 112), (237, 100), (150, 75), (250, 50)):
                hit = om.splat_hit(img, v, p, w, h, x, y)
                assert hit is not None
                o, d = om.mouse_ray(v, p, w, h, x, y)
                np.testing.assert_allclose(hit.point, o + hit.distance * d, atol=1e-9)  # on the mouse ray
                errors.append(hit.point[2] / -d[2])  # along the ray from the floor (> 0: beyond it)
            print(f"scale {scale}: floor hits along the ray from z = 0 (m): {np.round(errors, 4)}")
            assert max(map(abs, errors)) < 0.02, (scale, errors)
        sky_view = look_at_view_matrix((0, 0, 60.0), (1.0, 0, 100.0))  # above the room, looking up: nothing
        assert om.splat_hit(ovl.image(sky_view, p, 32, 20, slot="sky"), sky_view, p, 32, 20, 16, 10) is None
    finally:
        ovl.close()


def test_splats_win_uses_the_draw_rule():
    assert om.splats_win(3.0, None)
    assert om.splats_win(3.0, 3.5)  # the mesh is behind
    assert om.splats_win(3.0, 3.0 * (1 - om.DEPTH_PULL))  # within DEPTH_PULL: the splats are drawn over it
    assert not om.splats_win(3.0, 2.5)


@bpy_only
def test_click_selection_rules(blender):
    """picking.select_object selects as view3d.select does (click, Shift toggles, extend, deselect), and
    _picked tells which object view3d.select acted on from the selection before and after it."""
    bpy = blender
    from gs_ibl_addon.blender.viewport import picking
    objs = []
    for name in ("A", "B", "C"):
        o = bpy.data.objects.new(name, None)
        bpy.context.scene.collection.objects.link(o)
        objs.append(o)
    a, b, c = objs
    layer = bpy.context.view_layer
    a.select_set(True)
    layer.objects.active = a
    picking.select_object(bpy.context, b)  # a click: b only
    assert [o.name for o in bpy.context.selected_objects] == ["B"] and layer.objects.active == b
    picking.select_object(bpy.context, c, toggle=True)  # Shift+click adds and makes active
    assert {o.name for o in bpy.context.selected_objects} == {"B", "C"} and layer.objects.active == c
    picking.select_object(bpy.context, c, toggle=True)  # Shift+click on the active one deselects it
    assert [o.name for o in bpy.context.selected_objects] == ["B"]
    picking.select_object(bpy.context, a, extend=True)
    picking.select_object(bpy.context, b, deselect=True)
    assert [o.name for o in bpy.context.selected_objects] == ["A"]
    before = ({a: True, b: False, c: False}, a)
    assert picking._picked(before, ({a: False, b: True, c: False}, b)) == b
    assert picking._picked(before, ({a: False, b: False, c: False}, a)) is None  # clicked nothing: deselected all
    assert picking._picked(({a: True, b: True, c: False}, a), ({a: True, b: False, c: False}, a)) == b  # toggle off
    # the operators are registered with the extension; keymap items only where a window manager has keyconfigs
    assert bpy.ops.gs_ibl.cursor3d.poll() is False and bpy.ops.gs_ibl.select.poll() is False  # no 3D View here
