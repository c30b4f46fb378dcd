"""Settings from a tolerance (core/tolerance.py): the error estimate against the truth on small scenes, the chosen
setting within the tolerance, and bad tolerances refused.

Truth here: the same bake at 512^2 faces (exact filter from a 128^2 copy). Every face size reads the same
radiance (the probe's dilation has one size), and 128^2 is already within 0.1% of a 1024^2 render on the sample
environment (docs/accuracy.md), so the truth's own error is taken as TRUTH_ERR.
"""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.cli import main
from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.bake import RADIANCE_OUT_MAX, BadSetting, ProbeSettings, bake_probe, check_settings, relative_rms
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.tolerance import ErrorModel, check_tolerance, interpolation_error, plan_text, tail, upsample2

FACES = (32, 64, 128)
TRUTH_FACE = 512
BAND, FLOOR = 12.0, 0.005
TRUTH_ERR = 2e-4  # the truth's own error (512^2 against 1024^2): below it an estimate cannot be checked


def _scenes() -> dict:
    return {
        "room": (synthetic.room_scene().scene, np.array([0.0, 0.0, 1.5])),
        "sample_env": (synthetic.sample_environment(), np.array([0.0, 0.0, 1.0])),
        "sun": (synthetic.shell_scene(synthetic.radiance_functions()["sun"], 20_000), np.zeros(3)),
    }


@pytest.fixture(scope="module")
def baked():
    """Per scene: (scene, position, renderer, {face: irradiance at 16^2} for FACES and the truth)."""
    out, renderers = {}, []
    for name, (scene, pos) in _scenes().items():
        r = SplatRenderer(scene)
        renderers.append(r)
        irr = {f: bake_probe(scene, pos, ProbeSettings(face_size=f), renderer=r).irradiance for f in FACES}
        irr["truth"] = bake_probe(scene, pos, ProbeSettings(face_size=TRUTH_FACE, extra={"downsample_to": 128}),
                                  renderer=r).irradiance
        out[name] = (scene, pos, r, irr)
    yield out
    for r in renderers:
        r.close()


@pytest.mark.parametrize("name", ["room", "sample_env", "sun"])
def test_estimate_is_conservative_within_a_stated_band(baked, name):
    # calibrated on 32^2 -> 64^2, as the bake does. Measured (pooled error, lavapipe, 2026-12-03), estimate / true
    # at 64^2 and predicted at 128^2: room 0.067/0.042% and 0.033/0.006%, sample_env 2.0/0.34% and 1.0/0.10%, sun
    # 0.39/0.016% and 0.20/0.014%. Band asserted: the estimate is at least the true error (less the truth's own)
    # and at most BAND x it or FLOOR, whichever is more (below FLOOR no bake's choice depends on how tight it is).
    scene, pos, _r, irr = baked[name]
    model = ErrorModel()
    est64 = model.calibrate(32, 64, relative_rms(irr[32], irr[64]))
    true64 = relative_rms(irr[64], irr["truth"])
    true128 = relative_rms(irr[128], irr["truth"])
    assert true64 - TRUTH_ERR <= est64 <= max(BAND * true64, FLOOR), (est64, true64)
    assert true128 - TRUTH_ERR <= model.estimate(128) <= max(BAND * true128, FLOOR), (model.estimate(128), true128)
    # recalibrated on the next pair, the estimate still bounds the error
    est128 = model.calibrate(64, 128, relative_rms(irr[64], irr[128]))
    assert true128 - TRUTH_ERR <= est128 <= max(BAND * true128, FLOOR), (est128, true128)


@pytest.mark.parametrize("name,tol", [("room", 0.01), ("room", 0.002), ("sample_env", 0.05), ("sun", 0.01)])
def test_the_chosen_setting_meets_the_tolerance(baked, name, tol):
    scene, pos, r, irr = baked[name]
    p = bake_probe(scene, pos, ProbeSettings(tolerance=tol, max_face_size=TRUTH_FACE), renderer=r)
    st, plan = p.settings, p.settings["tolerance_plan"]
    assert plan["met"] and st["converged"] and plan["estimated_error"] <= tol
    assert relative_rms(p.irradiance, irr["truth"]) <= tol
    faces = [t["face_size"] for t in st["face_size_trials"]]
    # per-face sizes: the trials give the largest face; the cube written is at most RADIANCE_OUT_MAX
    assert faces[:2] == [32, 64] and st["face_size"] == plan["face_size"] == min(faces[-1], RADIANCE_OUT_MAX)
    assert max(st["face_sizes"]) == faces[-1]
    assert "estimated error" in plan_text(st)


def test_the_sample_does_not_double_through_every_size(baked):
    # the old rule rendered 32, 64, 128, 256 and 512 at 1% on the sample; the model jumps from 64^2
    scene, pos, r, irr = baked["sample_env"]
    p = bake_probe(scene, pos, ProbeSettings(tolerance=0.01, max_face_size=TRUTH_FACE), renderer=r)
    faces = [t["face_size"] for t in p.settings["face_size_trials"]]
    assert len(faces) <= 4 and p.settings["tolerance_plan"]["met"], faces


def test_irradiance_size_zero_is_chosen_by_the_error_between_texels(baked):
    scene, pos, r, _irr = baked["room"]
    p = bake_probe(scene, pos, ProbeSettings(face_size=64, irradiance_size=0, tolerance=0.01), renderer=r)
    m = p.settings["irradiance_size"]
    assert m in (8, 16, 32) and p.irradiance.shape == (6, m, m, 3)
    between = p.settings["tolerance_plan"]["irradiance_between_texels"]
    assert between[str(m)] <= 0.01 and all(between[k] > 0.01 for k in between if int(k) < m)


def test_the_splats_on_the_gpu_alone_choose_the_same(baked):
    # the estimate needs only the renders: a bake from a renderer without the host's splats chooses as one with them
    scene, pos, r, _irr = baked["sample_env"]
    s = ProbeSettings(tolerance=0.01, max_face_size=TRUTH_FACE)
    hosted, alone = bake_probe(scene, pos, s, renderer=r), bake_probe(None, pos, s, renderer=r)
    assert alone.settings["face_sizes"] == hosted.settings["face_sizes"]
    assert alone.settings["tolerance_plan"]["model"] == "change" and alone.settings["tolerance_plan"]["met"]


def test_tail_and_interpolation_helpers():
    assert tail(0.5, 1) == pytest.approx(1.0) and tail(0.5, 2) == pytest.approx(1 / 3)
    model = ErrorModel()
    assert model.calibrate(32, 64, 0.02) == pytest.approx(0.02) and model.estimate(256) == pytest.approx(0.005)
    assert model.calibrate(64, 128, 0.005) == pytest.approx(0.005 * tail(0.35, 1))  # a fast fall, clamped
    flat = np.full((6, 8, 8, 3), 0.7)
    np.testing.assert_allclose(upsample2(flat), np.full((6, 16, 16, 3), 0.7))
    assert interpolation_error(flat, np.full((6, 16, 16, 3), 0.7)) < 1e-12


@pytest.mark.parametrize("value", ["0", "0.0001", "0.9", "-1", "nan", "inf", "abc"])
def test_bad_tolerances_are_refused_by_the_command_line(value, capsys):
    with pytest.raises(SystemExit) as e:
        main(["bake", "X.ply", "--tolerance", value, "--out", "o"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--tolerance" in err and err.count("\n") == 1


@pytest.mark.parametrize("value", [0, 1e-4, 0.9, float("nan"), True, "0.01"])
def test_bad_tolerances_are_refused_by_the_core(value):
    with pytest.raises(BadSetting) as e:
        check_settings(ProbeSettings(tolerance=value))
    assert e.value.option == "tolerance"
    assert check_tolerance(0.01) == 0.01
