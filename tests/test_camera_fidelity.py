"""The final render's camera path (ViewBatch.camera + SplatRenderer.render, what F12 draws: blender/render/splats.py
render_layers) against the numpy reference (core/render/reference.py) on a real capture: a 9k-splat crop of the
guitar (tests/data/guitar.compressed.ply, the splats within 0.35 of its centre), colour rule off, 64x48 views: one
plain, one with a lens shift, one close up (splats 0.1 from the camera, over the image edges), and a render border's
window of a shifted 128x96 frame with a depth cut (FRONT and BEHIND).

Tolerance: every pixel within 1e-3 of the reference (premultiplied linear RGB and alpha) and PSNR >= 60 dB per view;
measured on lavapipe: largest difference 2e-5 or less. (How our frames compare with 3DGS's own look, gsplat's classic
rasterization, is benchmarks/fidelity_bench.py's measurement at 1920x1080: at 64x48 the pixel-sized dilation alone
keeps the two apart.)
"""
import math
import os

import numpy as np
import pytest

from gs_ibl_addon.core.formats import read_scene
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch

GUITAR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "guitar.compressed.ply")
NEAR = 0.05
MAX_ABS, MIN_PSNR = 1e-3, 60.0
TX = math.tan(math.radians(30))  # 60° across


def psnr(a, b) -> float:
    mse = float(np.mean((np.asarray(a, np.float64) - b) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(1.0 / mse)


@pytest.fixture(scope="module")
def crop():
    scene = read_scene(GUITAR)
    scene.colour_space = "linear"  # the colour rule off, as the fidelity benchmark compares
    centre = np.median(scene.positions.astype(np.float64), 0)
    s = scene.subset(np.flatnonzero(np.linalg.norm(scene.positions - centre, axis=1) < 0.35))
    r = SplatRenderer(s, near=NEAR)
    yield s, centre, r
    r.close()


def camera(centre, dist: float, azimuth: float) -> np.ndarray:
    """Blender's camera-to-world matrix of a camera ``dist`` from ``centre``, looking at it; the capture's up is -Y."""
    d = np.array([math.cos(math.radians(azimuth)), 0.0, math.sin(math.radians(azimuth))])
    f = -d
    up = np.array([0.0, -1.0, 0.0])
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = r, np.cross(r, f), -f, centre + dist * d
    return m


def check(name: str, got: np.ndarray, ref: np.ndarray) -> None:
    err = float(np.abs(got - ref).max())
    p = psnr(got, ref)
    assert err <= MAX_ABS and p >= MIN_PSNR, f"{name}: largest difference {err:.2e}, PSNR {p:.1f} dB"


@pytest.mark.parametrize("name, dist, azimuth, shift", [
    ("plain", 0.9, 0.0, (0.0, 0.0)),
    ("lens shift", 0.9, 60.0, (0.2 * 2 * TX, -0.1 * 2 * TX)),
    ("close up", 0.45, 200.0, (0.0, 0.0)),
])
def test_camera_view_matches_reference(crop, name, dist, azimuth, shift):
    scene, centre, r = crop
    batch = ViewBatch.camera(camera(centre, dist, azimuth), TX, TX * 48 / 64, 64, 48, shift=shift)
    got = r.render(batch).images[0]
    assert got[..., 3].mean() > 0.5  # the crop fills most of the frame
    check(name, got, render_reference(scene, batch, near=NEAR)[0])


def test_border_window_with_depth_cut_matches_reference(crop):
    """F12 with a render border and meshes: the window's pixels are the frame's, FRONT and BEHIND as the
    reference splits them at the cut."""
    scene, centre, r = crop
    m = camera(centre, 0.7, 120.0)
    window = (40, 30, 104, 78)
    full = ViewBatch.camera(m, TX, TX * 96 / 128, 128, 96, shift=(0.1, 0.05))
    batch = ViewBatch.camera(m, TX, TX * 96 / 128, 128, 96, shift=(0.1, 0.05), window=window)
    frame = r.render(full).images[0]
    cut = np.full((48, 64), 0.7, np.float32)  # a plane through the crop's centre on the left half, no mesh elsewhere
    cut[:, 32:] = np.inf
    res = r.render(batch, cut=cut)
    front, behind = res.images[0], res.behinds[0]
    plain = r.render(batch).images[0]
    assert np.array_equal(plain, frame[30:78, 40:104])  # a window's pixels are the full frame's, bit for bit
    ref_front, ref_behind = render_reference(scene, batch, near=NEAR, cut=cut)
    check("window FRONT", front, ref_front[0])
    check("window BEHIND", behind, ref_behind[0])
    assert behind[:, :32, 3].mean() > 0.05 and behind[:, 32:].max() == 0  # the cut split the left half only
