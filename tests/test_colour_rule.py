"""The colour rule (core/colour.py): what a splat's SH + 0.5 means, applied alike on the GPU, in the numpy reference,
on the command line and in probe.json; files say which rule they were made for."""
import json
import os

import numpy as np
import pytest

from gs_ibl_addon.cli import main
from gs_ibl_addon.core.colour import linear_to_srgb, splat_radiance, srgb_to_linear
from gs_ibl_addon.core.formats import read_scene
from gs_ibl_addon.core.formats.colour_space import (colour_space_comment, declared_colour_space,
                                                    resolve_colour_space)
from gs_ibl_addon.core.formats.ply import write_ply
from gs_ibl_addon.core.image_io import read_exr
from gs_ibl_addon.core.render.reference import render_reference
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc
from gs_ibl_addon.core.synthetic import random_scene, sample_environment, shell_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOL = 2e-4  # float32 GPU against float64 numpy (as tests/test_renderer.py)


def blender_srgb_to_linear(c: float) -> float:
    """Cycles' color_srgb_to_linear (intern/cycles/util/color.h), written out scalar by scalar."""
    if c < 0.04045:
        return 0.0 if c < 0.0 else c * (1.0 / 12.92)
    return ((c + 0.055) * (1.0 / 1.055)) ** 2.4


def test_srgb_to_linear_is_blenders_curve_on_every_value():
    c = np.array([-3.0, -1e-3, 0.0, 0.01, 0.04, 0.04045, 0.05, 0.2, 0.5, 0.73, 1.0, 1.5, 4.0, 40.0])
    np.testing.assert_allclose(srgb_to_linear(c), [blender_srgb_to_linear(x) for x in c], rtol=1e-12)
    assert abs(srgb_to_linear(0.5) - 0.214041) < 1e-6  # sRGB mid-grey is a fifth of the light
    assert srgb_to_linear(2.0) > 4.9  # extended above 1, never clamped
    x = np.linspace(0, 1, 101)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)


def test_splat_radiance_per_space():
    c = np.array([[-0.2, 0.5, 1.7]])
    np.testing.assert_allclose(splat_radiance(c, "linear"), [[0.0, 0.5, 1.7]])
    np.testing.assert_allclose(splat_radiance(c, "srgb"), [[0.0, srgb_to_linear(0.5), srgb_to_linear(1.7)]])
    with pytest.raises(ValueError, match="colour space 'rec2020'"):
        splat_radiance(c, "rec2020")
    empty = SplatScene.empty()
    with pytest.raises(ValueError, match="colour space 'sRGB'"):
        SplatScene(empty.positions, empty.scales, empty.rotations, empty.opacities, empty.sh, colour_space="sRGB")


@pytest.mark.parametrize("space", ["srgb", "linear"])
@pytest.mark.parametrize("sh_degree", [0, 3])
def test_gpu_matches_reference_in_both_spaces(space, sh_degree):
    scene = random_scene(400, seed=3, sh_degree=sh_degree, extent=2.0)
    scene.colour_space = space
    # bright enough that some colours pass 1 (the sRGB curve's extension) and some SH go negative
    scene.sh[:, 0] *= 1.8
    batch = ViewBatch.cubemap([0.1, -0.2, 0.05], 24)
    gpu = SplatRenderer(scene).render(batch).images
    ref = render_reference(scene, batch)
    for v, (a, b) in enumerate(zip(gpu, ref)):
        err = np.abs(a - b).max()
        assert err < TOL, f"{space}, view {v}: max |gpu - reference| = {err:.2e}"


def test_one_splat_in_each_space_and_switching_without_upload():
    rgb = np.array([1.5, 0.5, 0.02])
    scene = SplatScene(np.array([[0, 4, 0]], np.float32), np.full((1, 3), 0.3, np.float32),
                       np.array([[1, 0, 0, 0]], np.float32), np.array([0.99], np.float32),
                       rgb_to_sh_dc(rgb[None, None].astype(np.float32)))  # from outside: srgb by default
    assert scene.colour_space == "srgb"
    batch = ViewBatch.pinhole([0, 0, 0], [0, 1, 0], 10.0, 8, 8)
    with SplatRenderer(scene) as r:
        px = r.render(batch).images[0][4, 4]
        np.testing.assert_allclose(px[:3] / px[3], srgb_to_linear(rgb), rtol=1e-4)
        r.colour_space = "linear"  # a push constant: new commands, nothing uploaded again
        px = r.render(batch).images[0][4, 4]
        np.testing.assert_allclose(px[:3] / px[3], rgb, rtol=1e-4)


def test_files_declare_their_colour_space(tmp_path):
    # the bundled sample and every synthetic scene hold linear radiance and say so
    assert declared_colour_space(os.path.join(ROOT, "samples", "room.ply")) == "linear"
    assert read_scene(os.path.join(ROOT, "samples", "room.ply")).colour_space == "linear"
    assert sample_environment().colour_space == "linear"
    synthetic = tmp_path / "synthetic.ply"
    write_ply(synthetic, random_scene(50, seed=1))
    assert declared_colour_space(synthetic) == "linear" and read_scene(synthetic).colour_space == "linear"
    # a file from outside declares nothing: sRGB, as Blender reads it
    capture = random_scene(50, seed=1)
    capture.colour_space = "srgb"
    plain = tmp_path / "capture.ply"
    write_ply(plain, capture)
    assert declared_colour_space(plain) is None and read_scene(plain).colour_space == "srgb"
    assert resolve_colour_space("auto", plain) == "srgb" and resolve_colour_space("auto", synthetic) == "linear"
    assert resolve_colour_space("srgb", synthetic) == "srgb"
    assert colour_space_comment("linear") == "gs_ibl colour_space=linear"
    with pytest.raises(ValueError, match="--colour-space"):
        resolve_colour_space("display", plain)


@pytest.fixture(scope="module")
def grey_shell_ply(tmp_path_factory):
    """A closed shell of sRGB mid-grey (0.5) as a capture would store it: undeclared, so sRGB."""
    s = shell_scene(lambda d: np.full((len(d), 3), 0.5), 3000, radius=5.0)
    s.colour_space = "srgb"
    path = tmp_path_factory.mktemp("grey") / "grey.ply"
    write_ply(path, s)
    return path


@pytest.mark.parametrize("option, space, light", [(None, "srgb", 0.214041), ("linear", "linear", 0.5),
                                                  ("srgb", "srgb", 0.214041)])
def test_bake_uses_and_records_the_colour_space(grey_shell_ply, tmp_path, option, space, light):
    out = tmp_path / "probe"
    args = ["bake", str(grey_shell_ply), "--probe", "0", "0", "0", "--face-size", "32", "--out", str(out)]
    assert main(args + (["--colour-space", option] if option else [])) == 0
    assert json.loads((out / "probe.json").read_text())["settings"]["colour_space"] == space
    # inside a closed uniform shell the irradiance (E/pi) is the shell's radiance
    irr = read_exr(out / "irradiance.exr")[..., :3]
    np.testing.assert_allclose(irr.mean((0, 1)), light, rtol=0.01)


def test_render_and_cubemap_take_the_option(grey_shell_ply, tmp_path, capsys):
    out = tmp_path / "v.exr"
    assert main(["render", str(grey_shell_ply), "--camera", "0", "0", "0", "--look-at", "0", "1", "0",
                 "--size", "16", "16", "--out", str(out), "--colour-space", "linear"]) == 0
    np.testing.assert_allclose(read_exr(out)[..., :3].mean(), 0.5, rtol=0.01)
    assert main(["cubemap", str(grey_shell_ply), "--probe", "0", "0", "0", "--face-size", "8",
                 "--out", str(tmp_path / "cube")]) == 0
    np.testing.assert_allclose(read_exr(tmp_path / "cube" / "radiance.exr")[..., :3].mean(), 0.214041, rtol=0.01)
    assert "colour space srgb" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["bake", str(grey_shell_ply), "--colour-space", "rgb", "--out", str(tmp_path / "x")])
    assert e.value.code == 2 and "--colour-space" in capsys.readouterr().err


def test_scenes_of_both_spaces_combine_under_blenders_rule():
    """core.scene.combine_scenes (F12's splats and a probe lit by several splat objects): scenes of one space keep
    it; a mix is drawn by the sRGB rule with the linear scene re-encoded, so every splat's base colour gives the
    radiance its own rule gave (exact), and the GPU draws the combined scene as the reference does."""
    from dataclasses import replace
    from gs_ibl_addon.core.scene import combine_scenes
    a = replace(random_scene(300, seed=1, sh_degree=3, extent=2.0), colour_space="srgb")
    b = replace(random_scene(200, seed=2, sh_degree=1, extent=2.0), colour_space="linear")
    assert combine_scenes([a, replace(b, colour_space="srgb")]).colour_space == "srgb"
    assert combine_scenes([replace(a, colour_space="linear"), b]).colour_space == "linear"
    both = combine_scenes([a, b])
    assert both.colour_space == "srgb" and both.count == 500 and both.sh.shape[1] == 16
    C0 = 0.28209479177387814
    dc = lambda s: s.sh[:, 0] * C0 + 0.5  # noqa: E731
    np.testing.assert_allclose(splat_radiance(dc(both)[:300], "srgb"), splat_radiance(dc(a), "srgb"), rtol=1e-6)
    np.testing.assert_allclose(splat_radiance(dc(both)[300:], "srgb"), splat_radiance(dc(b), "linear"), rtol=1e-4,
                               atol=1e-6)
    batch = ViewBatch.cubemap([0.1, -0.2, 0.05], 16)
    gpu = SplatRenderer(both).render(batch).images
    ref = render_reference(both, batch)
    assert max(float(np.abs(g - r).max()) for g, r in zip(gpu, ref)) < 2e-4
