"""The renderer on a real capture (tests/data/guitar.compressed.ply, SuperSplat layout, MIT, PlayCanvas)."""
import os

import numpy as np

from gs_ibl_addon.core.formats import read_scene
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch

GUITAR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "guitar.compressed.ply")


def test_guitar_front_view_matches_reference_and_is_an_object():
    scene = read_scene(GUITAR)
    lo, hi = scene.bounds()
    centre = (lo + hi) / 2
    # the capture is Y-down; its front faces +X (docs/img/guitar_renderer.png shows four sides)
    batch = ViewBatch.pinhole(centre + np.array([1.2 * np.linalg.norm(hi - lo), 0, 0]), centre, 40, 40, 64,
                              up=(0, -1, 0))
    gpu = SplatRenderer(scene).render(batch).images[0]
    ref = render_reference(scene, batch)[0]
    # thousands of overlapping real splats per pixel: float32 against float64 drifts a little more than on
    # small synthetic scenes
    assert np.abs(gpu - ref).max() < 1e-3
    alpha = gpu[..., 3]
    assert 0.05 < alpha.mean() < 0.4  # an object in the middle, background around it
    assert alpha[[0, 0, -1, -1], [0, -1, 0, -1]].max() < 0.01  # corners are empty
    assert alpha[40, 20] > 0.95  # the body is solid
    # spatial coherence: neighbouring pixels agree far better than random pairs (an object, not noise)
    rgb = gpu[..., :3]
    neighbour = np.abs(rgb[:, 1:] - rgb[:, :-1]).mean()
    shuffled = np.abs(rgb.reshape(-1, 3) - np.random.default_rng(0).permutation(rgb.reshape(-1, 3))).mean()
    assert neighbour < 0.5 * shuffled
