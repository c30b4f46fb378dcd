"""The strip raster (gs_raster.glsl RASTER_STRIPS, renderer.RASTER_STRIPS): each strip of two pixel rows of a tile
composites only the pairs whose footprint may reach its rows. It must leave out only pairs that every pixel of the
strip would reject: checked in numpy (splat_math.strip_mask in float32, the GPU's arithmetic, against the footprint
test in float64 at every pixel centre of every tile) and on the device (the strip kernels' images and depths equal
to the plain kernels' bit for bit, at every face size and on sub-pixel shells)."""
import numpy as np
import pytest

from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.splat_math import STRIP_ROWS, plane_form, plane_form_m, prepare, strip_bits, strip_mask
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.vk import get_context
from gs_ibl_addon.core.vk.constants import TILE
from test_raster_plane import CASES, _far_scene, _mixed, _near_scene, _wall
from gs_ibl_addon.core.synthetic import concat


def _small_shell(n: int = 20_000, seed: int = 3):
    """A shell 5-6 m out of splats below a 64² pixel, opacity 0.8, stored shuffled (as a trained background)."""
    from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc
    rng = np.random.default_rng(seed)
    f32 = np.float32
    d = rng.standard_normal((n, 3)).astype(f32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pos = d * rng.uniform(5.0, 6.0, n).astype(f32)[:, None]
    rot = rng.standard_normal((n, 4)).astype(f32)
    rot /= np.linalg.norm(rot, axis=1, keepdims=True)
    scales = (rng.uniform(0.005, 0.05, (n, 1)) * rng.uniform(0.2, 1.0, (n, 3))).astype(f32)
    sh = rgb_to_sh_dc(rng.uniform(0.1, 0.9, (n, 3)).astype(f32))[:, None, :]
    return SplatScene(pos, scales, rot, np.full(n, 0.8, f32), sh.astype(f32), colour_space="linear")


@pytest.mark.parametrize("case", ["far", "wall"])
def test_strip_mask_holds_every_pixel_the_footprint_takes(case):
    if case == "far":
        scene, batch = concat([_near_scene(), _far_scene(1500)]), ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 64)
    else:
        scene, batch = _wall(1500), CASES["wall"][1]()
    p = prepare(scene, batch.origin, batch.dilation, energy_preserving=batch.energy_preserving)
    taken_total, reached, possible = 0, 0, 0
    for v in batch.views:
        form = plane_form(p, slice(None), v.forward, v.right, v.down)
        held = np.where(form.held & p.alive)[0]
        sub = type(form)(*[getattr(form, k)[held] for k in form.__dataclass_fields__])
        s = ((np.arange(v.width) + 0.5) / v.width * 2 - 1) * v.tan_x
        t = ((np.arange(v.height) + 0.5) / v.height * 2 - 1) * v.tan_y
        tt, ss = np.meshgrid(t, s, indexing="ij")
        m, _, ahead = plane_form_m(sub, ss.ravel(), tt.ravel())
        taken = ((m <= p.cutoff[held, None]) & ahead).reshape(len(held), v.height, v.width)
        # and as the GPU tests it, in float32 (composite: q > c den rejects)
        sub32 = type(sub)(*[getattr(sub, k).astype(np.float32) for k in sub.__dataclass_fields__])
        m32, _, ahead32 = plane_form_m(sub32, ss.ravel().astype(np.float32), tt.ravel().astype(np.float32))
        taken |= ((m32 <= p.cutoff[held, None].astype(np.float32)) & ahead32).reshape(taken.shape)
        step = 2 * v.tan_y / v.height
        for ty in range(-(-v.height // TILE)):
            mask = strip_mask(sub, p.cutoff[held], t[ty * TILE], step, np.float32)
            rows = taken[:, ty * TILE:(ty + 1) * TILE].any(axis=2)  # (S, rows of this tile) the footprint takes
            strip_of_row = np.arange(rows.shape[1]) // STRIP_ROWS
            bit = (mask[:, None] >> strip_of_row[None].astype(np.uint32)) & 1
            assert not (rows & (bit == 0)).any(), "a pixel the footprint test takes is outside its strip's mask"
            taken_total += taken[:, ty * TILE:(ty + 1) * TILE].sum()  # pixels
            # how selective: strips reached by the pairs that take a pixel in this tile row
            hit = rows.any(axis=1)
            reached += sum(bin(int(b)).count("1") for b in mask[hit])
            possible += hit.sum() * (TILE // STRIP_ROWS)
    assert taken_total > 1000
    assert reached < 0.6 * possible  # the masks leave most strips out for small splats


def test_strip_bits_of_needles_at_every_angle():
    """Thin ellipses (axis ratios up to 10^5 : 1, any angle, any offset) as the conic kernel tests them (conic_hit:
    Q = ds (A ds + B2 dt + D) + dt (C dt + E) + F <= 0, float32): every pixel centre Q takes lies in a strip its
    float32 bound lists. Needles past STRIP_MAX_COND take every strip (without that, 6% of these left a pixel out)."""
    f = np.float32
    rng = np.random.default_rng(1)
    n_px = 256
    centres = ((np.arange(n_px, dtype=f) + f(0.5)) / f(n_px) * f(2) - f(1))
    step = f(2) / f(n_px)
    hits, bounded = 0, 0
    for _ in range(2500):
        length, width = step * rng.uniform(2, 400), step * 10 ** rng.uniform(-2.5, 0.5)
        th = rng.uniform(0, np.pi)
        c, s = np.cos(th), np.sin(th)
        l1, l2 = 1 / width ** 2, 1 / length ** 2
        A, C, B2 = f(c * c * l1 + s * s * l2), f(s * s * l1 + c * c * l2), f(2 * c * s * (l1 - l2))
        s0, t0 = f(rng.uniform(-0.8, 0.8)), f(rng.uniform(-0.8, 0.8))
        ds, dt = (centres - s0)[None, :], (centres - t0)[:, None]
        taken = ~(ds * (A * ds + B2 * dt) + dt * (C * dt) + f(-1) > 0)
        rows = np.where(taken.any(axis=1))[0]
        if not len(rows):
            continue
        hits += 1
        for ty in np.unique(rows // TILE):
            bits = int(strip_bits(t0, A, B2, C, 0, 0, -1, centres[ty * TILE], step, np.float32))
            bounded += bits != 0xFF
            for r in rows[rows // TILE == ty] - ty * TILE:
                assert bits >> (r // STRIP_ROWS) & 1, (length / step, width / step, np.degrees(th))
    assert hits > 2000 and bounded > 200  # the rounder ones are bounded (their tiles not all 8 strips)


def test_strip_mask_of_a_footprint_between_rows_is_empty():
    # a tiny splat whose footprint lies between two rows' pixel centres reaches no strip (its pair is skipped)
    from gs_ibl_addon.core.scene import SplatScene
    v = ViewBatch.cubemap(np.zeros(3), 16).views[0]  # +X: down is -Z
    row = 2 * v.tan_y / v.height
    z = -(0.5 * row)  # t = 0: between rows 7 and 8 of the face's second tile row... of its only tile column
    scene = SplatScene(np.array([[10.0, 0.0, -10 * z]], np.float32), np.full((1, 3), 1e-4, np.float32),
                       np.array([[1, 0, 0, 0]], np.float32), np.array([0.9], np.float32),
                       np.full((1, 1, 3), 0.5, np.float32), colour_space="linear")
    p = prepare(scene, np.zeros(3), 0.0)
    form = plane_form(p, slice(None), v.forward, v.right, v.down)
    assert form.held.all()
    t_first = (0.5 / v.height * 2 - 1) * v.tan_y
    assert abs(form.t0[0] - (t_first + 7.5 * row)) < 1e-6 * row  # halfway between rows 7 and 8 of the tile
    assert strip_mask(form, p.cutoff, t_first, row, np.float32)[0] == 0
    scene.scales[:] = 0.2 * row * 10  # a footprint over both rows: strips 3 and 4
    p = prepare(scene, np.zeros(3), 0.0)
    form = plane_form(p, slice(None), v.forward, v.right, v.down)
    assert strip_mask(form, p.cutoff, t_first, row, np.float32)[0] == 0b11000


def _render(scene, batch, strips: bool, monkeypatch):
    monkeypatch.setattr(R, "RASTER_STRIPS", strips)
    r = R.SplatRenderer(scene, get_context())
    try:
        res = r.render(batch, depth=True)
        return res.images, res.depths, R.raster_kernel(batch, strips)
    finally:
        r.close()


FACES = {
    "wall": lambda: (_wall(), CASES["wall"][1]()),
    "mixed16": lambda: (_mixed(), ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 16)),
    "mixed64": lambda: (_mixed(), ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 64)),  # conic kernels
    "mixed512": lambda: (_mixed(), ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 512)),
    "shell32": lambda: (_small_shell(), ViewBatch.cubemap(np.array([0.3, 0.2, -0.1]), 32)),
    "shell128": lambda: (_small_shell(), ViewBatch.cubemap(np.array([0.3, 0.2, -0.1]), 128)),
}


@pytest.mark.parametrize("case", sorted(FACES))
def test_strip_kernels_draw_the_plain_kernels_images(case, monkeypatch):
    scene, batch = FACES[case]()
    plain, plain_z, plain_k = _render(scene, batch, False, monkeypatch)
    strips, strips_z, strips_k = _render(scene, batch, True, monkeypatch)
    assert strips_k == plain_k + "_strips"
    assert np.mean([img[..., 3].mean() for img in plain]) > 0.005  # not empty (as test_raster_plane)
    for a, b in zip(plain, strips):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(plain_z, strips_z):
        np.testing.assert_array_equal(a, b)


def test_strip_code_assumes_16_pixel_tiles():
    assert TILE == 16 and TILE // STRIP_ROWS == 8  # gs_raster.glsl: 8 strips a tile, bits 0xFF, rows 0..15


def test_strips_by_default_on_cpu_devices_only():
    ctx = get_context()
    assert R.RASTER_STRIPS is None and R.raster_strips(ctx) == bool(ctx.is_cpu)
    batch = ViewBatch.cubemap(np.zeros(3), 64)
    assert R.raster_kernel(batch, True) == "gs_raster_conic_strips" and R.raster_kernel(batch) == "gs_raster_conic"
    assert all(k in R.LOOP_PAIRS for k in ("gs_raster_strips", "gs_raster_conic_strips"))
