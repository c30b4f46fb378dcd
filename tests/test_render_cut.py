"""Camera frames for final renders (issue 36), the renderer's side: off-centre views and render borders
(ViewBatch.camera), and the depth cut that splits a frame into FRONT and BEHIND layers around a mesh
(SplatRenderer.render(cut=...), render_camera).

Checked on a synthetic wall of splats 4-5 m from a Blender-style camera, stored shuffled, with a tilted
85%-opaque quad that stands in front of the wall at one end and inside it at the other: every raster kernel (plain,
strips, conic, chunked with gs_merge_cut) and both emits draw FRONT and BEHIND as the numpy twin of the rule
(reference.render_reference(cut=...)), the exact cases hold bit for bit (cut = +inf: FRONT is the plain frame and
BEHIND 0; cut = 0: the other way round), and FRONT + (1 - FRONT.a) (mesh + (1 - mesh.a) BEHIND) is within the
issue's bounds of the mesh inserted at its depth into the splats' blend (reference.render_reference_mesh). A render
border's pixels are the full frame's bit for bit, and a lens shift is a window of a wider frame."""
import itertools
import pathlib
import re
import struct

import numpy as np
import pytest

from gs_ibl_addon.core.limits import TooBig
from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.reference import render_reference, render_reference_mesh
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc
from gs_ibl_addon.core.vk import get_context
from gs_ibl_addon.core.vk.constants import VIEW_BYTES, VIEW_ROWS

ROOT = pathlib.Path(__file__).resolve().parents[1]
TOL = 2e-4  # tests/test_renderer.py's: float32 on the GPU against float64 in numpy
# Blender's camera convention (looks down its -Z, +Y up): here looking along world +Y with +Z up
CAM = np.array([[1.0, 0, 0, 0.03], [0, 0, -1, -0.02], [0, 1, 0, 0.01], [0, 0, 0, 1]])
W, H = 128, 96  # 48 tiles: the conic kernel's range, and chunked where the targets ask
TAN_X = 0.5
GPU_TARGET = R.RASTER_TARGET_GROUPS


def _wall(n: int = 3500, seed: int = 1) -> SplatScene:
    """A wall of splats 4-5 m along +Y across the whole view, 3-9 cm, anisotropic, opacity 0.25-0.95; shuffled."""
    rng = np.random.default_rng(seed)
    f32 = np.float32
    pos = np.stack([rng.uniform(-2.6, 2.6, n), rng.uniform(4.0, 5.0, n), rng.uniform(-1.9, 1.9, n)], 1)
    scales = rng.uniform(0.03, 0.09, (n, 1)) * rng.uniform(0.35, 1.0, (n, 3))
    rot = rng.standard_normal((n, 4))
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    sh = rgb_to_sh_dc(rng.uniform(0.15, 0.95, (n, 3)).astype(f32))[:, None, :]
    scene = SplatScene(pos.astype(f32), scales.astype(f32), rot.astype(f32), rng.uniform(0.25, 0.95, n).astype(f32),
                       sh.astype(f32), colour_space="linear")
    return scene.subset(rng.permutation(n))


def _batch(width: int = W, height: int = H, shift=(0.0, 0.0), window=None) -> ViewBatch:
    return ViewBatch.camera(CAM, TAN_X, TAN_X * height / width, width, height, shift, window)


def _mesh(view) -> tuple[np.ndarray, np.ndarray]:
    """A quad x in [-1.2, 1.2], z in [-0.8, 0.8] whose depth along the view axis runs from 3.5 (in front of the wall)
    at its left edge to 4.8 (inside it) at its right, 85% opaque, its coverage 4x4-supersampled (anti-aliased edges).
    (premultiplied RGBA (H, W, 4), depth (H, W): the plane's depth at the pixel centre, +inf off the quad)."""
    s, t = view.image_coords()
    o = CAM[:3, 3]
    b = 1.3 / 2.4  # z = 3.5 + b (x + 1.2), x = o_x + s z
    a = 3.5 + b * (1.2 + o[0])
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    ss = s[None, :, None, None] + sub[None, None, None, :] * (s[1] - s[0])
    ts = t[:, None, None, None] + sub[None, None, :, None] * (t[1] - t[0])
    z = a / (1 - b * ss)
    x, up = o[0] + ss * z, o[2] - ts * z
    cover = ((x > -1.2) & (x < 1.2) & (up > -0.8) & (up < 0.8)).mean((2, 3))
    zc = np.broadcast_to(a / (1 - b * s), cover.shape)
    colour = np.stack([0.9 - 0.2 * (zc - 3.5), np.full_like(zc, 0.35), 0.15 + 0.3 * (zc - 3.5)], -1)
    alpha = 0.85 * cover
    rgba = np.concatenate([colour * alpha[..., None], alpha[..., None]], -1).astype(np.float32)
    return rgba, np.where(cover > 0, zc, np.inf).astype(np.float32)


def _over(front, mesh, behind):
    """The caller's composite: FRONT over (the mesh over BEHIND), premultiplied."""
    return front + (1 - front[..., 3:]) * (mesh + (1 - mesh[..., 3:]) * behind)


def _relative_error(got, want):
    """Per pixel: the largest RGB difference relative to the pixel's value (its largest channel, at least 0.05)."""
    return np.abs(got - want)[..., :3].max(-1) / np.maximum(want[..., :3].max(-1), 0.05)


# every raster kernel (plain / strips, with or without the conic pre-test, chunked or not) and both emits
VARIANTS = list(itertools.product(("plain", "strips"), ("slot", "splat"), (False, True), (False, True)))
IDS = [f"{r}-{e}{'-conic' if c else ''}{'-chunked' if k else ''}" for r, e, c, k in VARIANTS]


def _configure(monkeypatch, raster: str, emit: str, conic: bool, chunked: bool) -> None:
    monkeypatch.setattr(R, "RASTER_STRIPS", raster == "strips")
    monkeypatch.setattr(R, "EMIT_PER_SPLAT", emit == "splat")
    if not conic:
        monkeypatch.setattr(R, "CONIC_MAX_FACE", 0)
    target = GPU_TARGET if chunked else 1  # chunked also on a CPU device, or one chunk on any
    monkeypatch.setattr(R, "CPU_RASTER_TARGET_GROUPS", target)
    monkeypatch.setattr(R, "RASTER_TARGET_GROUPS", target)


def _check_kernels(r, raster, conic, chunked, cut=True):
    name = "gs_raster" + ("_conic" if conic else "") + ("_strips" if raster == "strips" else "") + \
        ("_cut" if cut else "")
    assert r.kernels["raster"] == name
    assert (r.chunks > 1) == chunked


@pytest.fixture(scope="module")
def wall():
    """The scene, the frame, the mesh and the two references (computed once: numpy takes a few seconds)."""
    scene, batch = _wall(), _batch()
    rgba, depth = _mesh(batch.views[0])
    fronts, behinds, depths = render_reference(scene, batch, with_depth=True, cut=depth)
    return {"scene": scene, "batch": batch, "mesh": rgba, "cut": depth, "twin": (fronts[0], behinds[0], depths[0]),
            "inserted": render_reference_mesh(scene, batch, rgba, depth)[0]}


# ---- the View interface -------------------------------------------------------------------------------------

def _spirv_view_struct(name: str, binding: int) -> tuple[list[int], int]:
    """The member offsets of the element struct of the runtime array in storage buffer ``binding`` of a kernel's
    SPIR-V, and that array's stride."""
    data = (ROOT / "gs_ibl_addon" / "shaders" / f"{name}.spv").read_bytes()
    words = struct.unpack(f"<{len(data) // 4}I", data)
    members, offsets, stride, pointers, runtime, bindings = {}, {}, {}, {}, {}, {}
    i = 5
    while i < len(words):
        count, op = words[i] >> 16, words[i] & 0xFFFF
        a = words[i + 1:i + count]
        if op == 30:  # OpTypeStruct
            members[a[0]] = list(a[1:])
        elif op == 29:  # OpTypeRuntimeArray
            runtime[a[0]] = a[1]
        elif op == 32:  # OpTypePointer
            pointers[a[0]] = a[2]
        elif op == 59:  # OpVariable
            bindings.setdefault("vars", {})[a[1]] = a[0]
        elif op == 71 and a[1] == 33:  # OpDecorate Binding
            bindings[a[0]] = a[2]
        elif op == 71 and a[1] == 6:  # OpDecorate ArrayStride
            stride[a[0]] = a[2]
        elif op == 72 and a[2] == 35:  # OpMemberDecorate Offset
            offsets[(a[0], a[1])] = a[3]
        i += count
    var = next(v for v, b in bindings.items() if v != "vars" and b == binding)
    block = pointers[bindings["vars"][var]]
    array = members[block][0]
    element = runtime[array]
    return [offsets[(element, m)] for m in range(len(members[element]))], stride[array]


def test_the_view_struct_is_declared_once():
    """VIEW_ROWS is the one declaration: constants.glsl's struct is generated from it (tests/test_kernels.py checks
    the file is current), no shader declares another, every kernel reading views compiled it with VIEW_ROWS' row
    offsets and stride, and the renderer packs a View's values by its names."""
    constants = (ROOT / "shaders" / "constants.glsl").read_text()
    assert constants.count("struct View {") == 1
    for line, (name, kind, parts) in zip(re.findall(r"^    (\w+ \w+;.*)$", constants, re.M), VIEW_ROWS):
        assert line == f"{kind} {name};  // {parts}"
    others = [p.name for p in (ROOT / "shaders").glob("*") if p.name != "constants.glsl" and "struct View" in
              p.read_text()]
    assert others == []
    for kernel, binding in (("gs_preprocess", 4), ("gs_emit", 0), ("gs_emit_per_splat", 0), ("gs_raster", 0),
                            ("gs_raster_strips_cut", 0), ("gs_raster_conic_cut", 0)):
        offsets, stride = _spirv_view_struct(kernel, binding)
        assert offsets == [16 * k for k in range(len(VIEW_ROWS))] and stride == VIEW_BYTES, kernel
    view = _batch(shift=(0.1, -0.05), window=(5, 7, 100, 90)).views[0]
    values = R.view_values(view, tile_base=11, pixel_base=222)
    words = R.pack_view(values)
    assert words.nbytes == VIEW_BYTES
    for row, (_, kind, parts) in enumerate(VIEW_ROWS):
        got = words[4 * row:4 * row + 4]
        got = got if kind.startswith("u") else got.view(np.float32)
        for k, part in enumerate(parts.split()):
            if part != "-":
                want = np.ravel(values[part])[parts.split()[:k].count(part)]
                assert got[k] == np.asarray(want).astype(got.dtype), (part, got[k], want)
    assert (values["x0"], values["y0"], values["width"], values["frame_width"]) == (5, 7, 95, W)


# ---- off-centre views and render borders ----------------------------------------------------------------------

def test_camera_takes_blender_s_convention():
    m = np.diag([2.0, 2.0, 2.0, 1.0])  # a scaled camera at the origin, looking down -Z
    m[:3, 3] = (1, 2, 3)
    b = ViewBatch.camera(m, 0.4, 0.3, 41, 31, shift=(0.1, 0.05))
    v = b.views[0]
    np.testing.assert_allclose(b.origin, [1, 2, 3])
    np.testing.assert_allclose(np.stack([v.forward, v.right, v.down]), [[0, 0, -1], [1, 0, 0], [0, -1, 0]],
                               atol=1e-15)
    assert b.pixel_angle == pytest.approx(2 * 0.4 / 41)
    # the centre pixel looks along forward + shift_x right + shift_y up
    np.testing.assert_allclose(v.pixel_directions()[15, 20], [0.1, 0.05, -1], atol=1e-12)
    # the frame's corner pixels reach tan -+ half a pixel from the shifted centre
    d = v.pixel_directions()
    np.testing.assert_allclose(d[0, 0], [0.1 - 0.4 + 0.4 / 41, 0.05 + 0.3 - 0.3 / 31, -1], atol=1e-12)
    w = ViewBatch.camera(m, 0.4, 0.3, 41, 31, shift=(0.1, 0.05), window=(3, 4, 20, 31)).views[0]
    np.testing.assert_array_equal(w.pixel_directions(), d[4:31, 3:20])
    for bad in ((0, 0, 0, 5), (-1, 0, 5, 5), (0, 0, 42, 5), (5, 5, 3, 9)):
        with pytest.raises(ValueError, match="window"):
            ViewBatch.camera(m, 0.4, 0.3, 41, 31, window=bad)
    with pytest.raises(ValueError, match="tan_x"):
        ViewBatch.camera(m, 0.0, 0.3, 41, 31)
    with pytest.raises(ValueError, match="4x4"):
        ViewBatch.camera(np.eye(3), 0.4, 0.3, 41, 31)


def _agree_but_for_flips(a, b, tol=1e-5, flips=0.002):
    """Equal to ``tol`` but where a footprint's edge fell on the other side of a pixel centre in float32 (an alpha
    step of 1/255 x the splat's opacity), at most ``flips`` of the pixels."""
    d = np.abs(a - b).max(-1)
    assert (d > tol).mean() <= flips and d.max() < 0.02, (d.max(), (d > tol).mean())


def test_lens_shift_is_a_window_of_a_wider_frame():
    """A camera shifted by its own half size is a quarter of a frame twice as wide and high: the same rays to
    float rounding (numpy), the same image on the GPU but for the rounding's footprint-edge flips, and both the
    numpy reference's."""
    scene = _wall()
    ty = TAN_X * H / W
    # the frame's centre moved right and up by its half width and height
    shifted = ViewBatch.camera(CAM, TAN_X / 2, ty / 2, W, H, shift=(TAN_X / 2, ty / 2))
    quarter = ViewBatch.camera(CAM, TAN_X, ty, 2 * W, 2 * H, window=(W, 0, 2 * W, H))
    np.testing.assert_allclose(shifted.views[0].pixel_directions(), quarter.views[0].pixel_directions(), atol=1e-12)
    with R.SplatRenderer(scene, get_context()) as r:
        a = r.render(shifted).images[0]
        b = r.render(quarter).images[0]
    assert a[..., 3].mean() > 0.5  # the wall is in view
    _agree_but_for_flips(a, b)
    _agree_but_for_flips(a, render_reference(scene, shifted)[0])


@pytest.mark.parametrize("raster,emit", [("plain", "slot"), ("strips", "splat")])
@pytest.mark.parametrize("conic", [False, True])
def test_a_border_is_the_crop_of_the_frame(monkeypatch, raster, emit, conic):
    """A render border (ViewBatch.camera's window) draws the full frame's pixels in it bit for bit, with and without
    a depth cut, windows not on the tile grid, down to one pixel; the kernels go by the frame's size."""
    _configure(monkeypatch, raster, emit, conic, chunked=False)
    scene = _wall()
    full = _batch(shift=(0.07, -0.04))
    _, cut = _mesh(full.views[0])
    with R.SplatRenderer(scene, get_context()) as r:
        res = r.render(full, depth=True)
        img, dep = res.images[0].copy(), res.depths[0].copy()
        _check_kernels(r, raster, conic, False, cut=False)
        res = r.render(full, cut=cut)
        front, behind = res.images[0].copy(), res.behinds[0].copy()
        for x0, y0, x1, y1 in ((37, 21, 121, 77), (0, 0, 17, 96), (100, 90, 128, 96), (64, 40, 65, 41)):
            win = _batch(shift=(0.07, -0.04), window=(x0, y0, x1, y1))
            res = r.render(win, depth=True)
            np.testing.assert_array_equal(res.images[0], img[y0:y1, x0:x1])
            np.testing.assert_array_equal(res.depths[0], dep[y0:y1, x0:x1])
            _check_kernels(r, raster, conic, False, cut=False)
            res = r.render(win, cut=cut[y0:y1, x0:x1])
            np.testing.assert_array_equal(res.images[0], front[y0:y1, x0:x1])
            np.testing.assert_array_equal(res.behinds[0], behind[y0:y1, x0:x1])


def test_a_chunked_border_agrees_with_the_frame(monkeypatch):
    """A small border (few tiles) is chunked where its frame is not: the same up to the merge's rounding."""
    _configure(monkeypatch, "strips", "splat", False, chunked=False)
    scene = _wall()
    with R.SplatRenderer(scene, get_context()) as r:
        img = r.render(_batch()).images[0]
        monkeypatch.setattr(R, "CPU_RASTER_TARGET_GROUPS", GPU_TARGET)
        monkeypatch.setattr(R, "RASTER_TARGET_GROUPS", GPU_TARGET)
        win = r.render(_batch(window=(40, 30, 88, 62))).images[0]
        assert r.chunks > 1
    np.testing.assert_allclose(win, img[30:62, 40:88], atol=TOL)


# ---- the depth cut ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("variant", VARIANTS, ids=IDS)
def test_cut_layers(monkeypatch, wall, variant):
    """Per kernel variant: cut = +inf gives FRONT == the plain frame and BEHIND == 0, cut = 0 the other way round,
    bit for bit (depths too); with the mesh's cut FRONT, BEHIND and the depth are the numpy twin's, and the
    composite with the mesh is within the issue's bounds of the mesh inserted into the splats' blend."""
    raster, emit, conic, chunked = variant
    _configure(monkeypatch, *variant)
    batch = wall["batch"]
    with R.SplatRenderer(wall["scene"], get_context()) as r:
        res = r.render(batch, depth=True)
        plain, plain_depth = res.images[0].copy(), res.depths[0].copy()
        _check_kernels(r, raster, conic, chunked, cut=False)
        plain_chunks = r.chunks
        for value in (np.inf, 0.0):
            res = r.render(batch, depth=True, cut=np.full((H, W), value, np.float32))
            _check_kernels(r, raster, conic, chunked)
            assert r.chunks == plain_chunks
            layers = (res.images[0], res.behinds[0])
            np.testing.assert_array_equal(layers[value == 0], plain)
            assert not layers[value != 0].any()
            np.testing.assert_array_equal(res.depths[0], plain_depth)
        res = r.render(batch, depth=True, cut=wall["cut"])
        front, behind, depth = res.images[0], res.behinds[0], res.depths[0]
    assert plain[..., 3].mean() > 0.7  # the wall covers the frame
    twin_front, twin_behind, twin_depth = wall["twin"]
    _agree_but_for_flips(front, twin_front, tol=TOL)
    _agree_but_for_flips(behind, twin_behind, tol=TOL)
    _agree_but_for_flips(depth[..., None] / 5, twin_depth[..., None] / 5, tol=TOL)  # depths of 4-5 m
    # the measure: the caller's composite against the mesh inserted at its depth into the blend (0.08% and
    # 1.9% here; 0.08-0.11% and 1.9-2.9% over the walls of seeds 1, 2, 3 and 5)
    mesh, inserted = wall["mesh"], wall["inserted"]
    err = _relative_error(_over(front, mesh, behind), inserted)
    assert err.mean() <= 0.01 and np.percentile(err, 99) <= 0.03, (err.mean(), np.percentile(err, 99))
    # ... on the mesh's own pixels too, on average (p99 there 5.6%: the GPU takes a splat straddling the surface on
    # the side of its closest approach to each ray, the reference by its centre's depth)
    on_mesh = np.isfinite(wall["cut"])
    assert err[on_mesh].mean() <= 0.01, err[on_mesh].mean()


def test_the_mesh_reference_at_its_limits():
    """render_reference_mesh with no mesh is the splats' frame, with the mesh nearer than every splat the mesh over
    them, and farther than every splat the splats over it; the twin's layers at those cuts are the frame and 0."""
    scene, batch = _wall(600), _batch(32, 24)
    plain = render_reference(scene, batch)[0].astype(np.float64)
    rng = np.random.default_rng(2)
    a = rng.uniform(0.3, 1.0, (24, 32, 1))
    mesh = np.concatenate([rng.uniform(0, 1, (24, 32, 3)) * a, a], -1).astype(np.float32)
    none = render_reference_mesh(scene, batch, mesh, np.full((24, 32), np.inf))[0]
    near = render_reference_mesh(scene, batch, mesh, np.full((24, 32), 0.5))[0]
    far = render_reference_mesh(scene, batch, mesh, np.full((24, 32), 50.0))[0]
    zero = np.zeros_like(mesh)
    np.testing.assert_allclose(none, plain, atol=1e-6)
    # (the blend stops where its transmittance falls below 1e-4: at another splat when a mesh is in it)
    np.testing.assert_allclose(near, _over(mesh, zero, plain), atol=1e-4)
    np.testing.assert_allclose(far, _over(plain, zero, mesh), atol=1e-4)
    for cut, layer in ((0.5, 1), (50.0, 0)):
        layers = render_reference(scene, batch, cut=np.full((24, 32), cut))
        np.testing.assert_allclose(layers[layer][0], plain, atol=1e-6)
        assert not layers[1 - layer][0].any()


def test_the_mesh_scene_tests_both_occlusions(wall):
    """The quad's near end stands in front of the wall and its far end inside it: the inserted reference is the mesh
    over the splats at one end and neither that nor the splats over the mesh at the other."""
    mesh, inserted, cut = wall["mesh"], wall["inserted"], wall["cut"]
    front, behind, _ = wall["twin"]
    splats = _over(front, np.zeros_like(mesh), behind)
    mesh_over = _relative_error(_over(mesh, 0 * mesh, splats), inserted)
    splats_over = _relative_error(_over(splats, 0 * mesh, mesh), inserted)
    on_mesh = np.isfinite(cut) & (mesh[..., 3] > 0.8)
    cols = np.where(on_mesh.any(0))[0]
    near, far = (np.zeros_like(on_mesh) for _ in range(2))
    near[:, cols[: len(cols) // 4]] = far[:, cols[-len(cols) // 4:]] = True
    near, far = near & on_mesh, far & on_mesh
    assert front[..., 3][near].mean() < 0.02 and mesh_over[near].max() < 1e-3 and splats_over[near].mean() > 0.2
    assert front[..., 3][far].mean() > 0.3 and mesh_over[far].mean() > 0.1 and splats_over[far].mean() > 0.05


# ---- render_camera ----------------------------------------------------------------------------------------------

def test_render_camera(wall):
    scene, batch, cut = wall["scene"], wall["batch"], wall["cut"]
    with R.SplatRenderer(scene, get_context()) as r:
        frame = r.render_camera(batch, cut=cut)
        assert frame.front.shape == frame.behind.shape == (H, W, 4) and frame.depth.shape == (H, W)
        assert frame.front.dtype == np.float32 and frame.kernels["raster"].endswith("_cut")
        assert frame.timings["wall"] > 0 and ("raster" in frame.timings or not r.ctx.timestamps_supported)
        _agree_but_for_flips(frame.front, wall["twin"][0], tol=TOL)
        plain = r.render_camera(batch, depth=False)
        assert plain.depth is None and not plain.behind.any() and not plain.kernels["raster"].endswith("_cut")
        win = r.render_camera(_batch(window=(10, 20, 70, 50)), cut=cut[20:50, 10:70])
        np.testing.assert_allclose(win.front, frame.front[20:50, 10:70], atol=TOL)  # maybe chunked: rounding
        with pytest.raises(ValueError, match="shape"):
            r.render_camera(batch, cut=cut[:10])
        with pytest.raises(ValueError, match="NaN"):
            r.render_camera(batch, cut=np.full((H, W), np.nan, np.float32))
        with pytest.raises(ValueError, match="one camera view"):
            r.render_camera(ViewBatch.cubemap([0, 0, 0], 16))
        with pytest.raises(ValueError, match="probes"):
            r.render(ViewBatch.cubemaps([[0, 0, 0], [1, 0, 0]], 16), cut=np.zeros((16, 16)))


def test_a_frame_too_large_is_refused_with_the_size_that_fits():
    ctx = get_context()
    side = int((R._binding_limit(ctx) / 16) ** 0.5 * 1.3)  # a frame whose image is past one storage binding
    w, h = 16 * side // 9, side * 9 // 16
    fit_w, fit_h = R.largest_camera_frame(ctx, w, h)
    assert fit_w * fit_h * 16 <= R._binding_limit(ctx) and fit_w < w and abs(fit_w / fit_h - w / h) < 0.01
    assert R.largest_camera_frame(ctx, fit_w, fit_h) == (fit_w, fit_h)
    with R.SplatRenderer(_wall(100), ctx) as r:
        with pytest.raises(TooBig, match=f"render {fit_w}x{fit_h} or smaller"):
            r.render_camera(ViewBatch.camera(CAM, TAN_X, TAN_X * h / w, w, h))


def test_more_pairs_than_a_buffer_holds_are_refused(monkeypatch):
    """A frame whose (tile, splat) pairs outgrow one storage binding is refused once counted, naming the share of
    its size that fits (here with the binding limit lowered: 40,000 pairs)."""
    scene = _wall(3000)
    scene.scales = (scene.scales * 6).astype(np.float32)  # splats over many tiles: ~100k pairs
    monkeypatch.setattr(R, "_binding_limit", lambda ctx: 4 * 40_000)
    with R.SplatRenderer(scene, get_context()) as r:
        with pytest.raises(TooBig, match=r"\(tile, splat\) pairs, more than .* \(40,000\): render \d+x\d+ or smaller"):
            r.render(_batch(256, 192))
