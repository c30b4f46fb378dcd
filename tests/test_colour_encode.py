"""Linear scenes as Blender's native splats: stored colours that Blender's sRGB decoding turns back into the linear
radiance (core/colour.py linear_to_srgb_extended, linear_sh_for_srgb_rule)."""
from __future__ import annotations

import numpy as np

from gs_ibl_addon.core.colour import linear_sh_for_srgb_rule, linear_to_srgb_extended, splat_radiance, srgb_to_linear
from gs_ibl_addon.core.sh import eval_sh_color
from gs_ibl_addon.core.synthetic import random_scene


def test_extended_encoding_inverts_blenders_curve_above_one():
    x = np.array([0.0, 1e-4, 0.0031308, 0.01, 0.21, 1.0, 5.0, 33.0])
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb_extended(x)), x, rtol=1e-12, atol=1e-15)
    assert linear_to_srgb_extended(np.array([5.0]))[0] > 1.9  # not clamped: an HDR lamp stays bright
    assert linear_to_srgb_extended(np.array([-1.0]))[0] == 0.0


def test_linear_scene_reencoded_decodes_to_its_radiance():
    scene = random_scene(200, seed=4, sh_degree=3)
    scene.sh[:, 0] *= 3.0  # HDR DC colours, some above 1
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    enc = linear_sh_for_srgb_rule(scene.sh)
    # the DC colour exactly
    dc_only = lambda sh: eval_sh_color(sh[:, :1], dirs)  # noqa: E731
    np.testing.assert_allclose(splat_radiance(dc_only(enc), "srgb"), splat_radiance(dc_only(scene.sh), "linear"),
                               rtol=1e-5, atol=1e-6)
    # view dependence to first order: small bands -> small error
    small = scene.sh.copy()
    small[:, 1:] *= 0.05
    want = splat_radiance(eval_sh_color(small, dirs), "linear")
    got = splat_radiance(eval_sh_color(linear_sh_for_srgb_rule(small), dirs), "srgb")
    lit = want.min(1) > 0.05
    assert np.median(np.abs(got[lit] / want[lit] - 1)) < 0.01
