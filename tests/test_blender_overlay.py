"""Viewport overlay logic: viewport matrices -> our renderer's camera -> the splat image the draw handler shows.

The bpy module cannot draw (GPU drawing raises in background mode), so what is tested is everything up to the
texture: the matrix conversion (against ViewBatch.pinhole and against Blender's own camera matrices), the image
(against the numpy reference renderer), re-rendering only on a view change, and the handler's object cache.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from gs_ibl_addon.blender.overlay_math import (SplatOverlay, ViewMotion, linear_to_srgb, look_at_view_matrix,
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
    np.testing.assert_allclose(r.render(ov.batch).images[0], r.render(ref).images[0], atol=1e-5)


@bpy_only
def test_handler_image_follows_the_splat_object(blender):
    """splat_image (what draw_callback draws) renders the object in world space, caches its upload, and uploads
    again when the object moves; the overlay toggle hides the point proxy."""
    bpy = blender
    from gs_ibl_addon.blender import overlay
    from gs_ibl_addon.blender.splat_object import PROXY_MODIFIER, create_splat_object, scene_from_object
    from mathutils import Matrix
    obj = create_splat_object(bpy.context, small_scene(), "S")
    rv3d = SimpleNamespace(view_matrix=Matrix(look_at_view_matrix(POS, TARGET).tolist()),
                           window_matrix=Matrix(perspective_matrix(60.0, 40, 30).tolist()))
    img = overlay.splat_image(obj, rv3d, 40, 30, 1.0)
    ref = render_reference(scene_from_object(obj), img.view.batch)[0]
    assert np.abs(img.rgba - ref).max() < TOL and img.rgba[..., 3].max() > 0.5
    first = overlay.overlay_for(obj)
    assert overlay.overlay_for(obj) is first
    obj.location = (0.5, 0.0, 0.0)
    bpy.context.view_layer.update()
    img2 = overlay.splat_image(obj, rv3d, 40, 30, 1.0)
    assert overlay.overlay_for(obj) is not first
    assert np.abs(img2.rgba - render_reference(scene_from_object(obj), img2.view.batch)[0]).max() < TOL
    settings = bpy.context.scene.gs_ibl_overlay
    settings.show = False
    assert not overlay._overlays  # images freed when off


@bpy_only
def test_display_settings_never_upload_again_and_helpers_hide(blender):
    """Show Splats, Resolution and Exposure are display-only: however often they change (with the depsgraph
    evaluated in between, as in the GUI), the splats are not read or uploaded again; while the overlay shows, the
    point proxy draws nothing (fraction 0), and its fraction comes back after. An edit of the mesh still uploads."""
    bpy = blender
    from gs_ibl_addon.blender import overlay, splat_cache
    from gs_ibl_addon.blender.compat import get_modifier_input, modifier_input_identifiers
    from gs_ibl_addon.blender.splat_object import PROXY_MODIFIER, create_splat_object
    from mathutils import Matrix
    obj = create_splat_object(bpy.context, small_scene(), "S")
    mod = obj.modifiers[PROXY_MODIFIER]
    frac = modifier_input_identifiers(mod.node_group)["Fraction"]
    f0 = get_modifier_input(mod, frac)
    rv3d = SimpleNamespace(view_matrix=Matrix(look_at_view_matrix(POS, TARGET).tolist()),
                           window_matrix=Matrix(perspective_matrix(60.0, 40, 30).tolist()))
    bpy.context.view_layer.update()
    overlay.splat_image(obj, rv3d, 40, 30, 1.0)
    n0 = splat_cache.uploads
    settings = bpy.context.scene.gs_ibl_overlay
    for step in range(3):
        settings.show = True
        bpy.context.view_layer.update()
        assert get_modifier_input(mod, frac) == 0.0 and obj.modifiers[PROXY_MODIFIER].show_viewport
        settings.exposure = 1.5 - step
        settings.resolution_scale = 0.3 + 0.2 * step
        bpy.context.view_layer.update()
        overlay.splat_image(obj, rv3d, 40, 30, settings.resolution_scale)
        settings.show = False
        bpy.context.view_layer.update()
        assert get_modifier_input(mod, frac) == pytest.approx(f0) and overlay.HIDDEN_KEY not in obj.keys()
        overlay.splat_image(obj, rv3d, 40, 30, 1.0)
    assert splat_cache.uploads == n0
    obj.data.vertices[0].co.x += 0.25  # a real edit
    obj.data.update()
    bpy.context.view_layer.update()
    overlay.splat_image(obj, rv3d, 40, 30, 1.0)
    assert splat_cache.uploads == n0 + 1


@bpy_only
def test_panel_wraps_long_lines(blender):
    from gs_ibl_addon.blender.panel import wrapped_lines
    report = ("Baked 21,939 splats, 512x512 faces\nexact; face size by irradiance change (64: 7.45%, 128: 3.32%, "
              "256: 1.50%, 512: 0.61%) converged")
    lines = wrapped_lines(report, 30)
    assert all(len(x) <= 30 for x in lines) and len(lines) >= 4
    assert " ".join(lines).split() == report.split()  # nothing lost, words kept whole
