"""bake_probes follows bake_probe's rules: the face size from the tolerance's error model (one model per probe, the
worst deciding), the same tolerance_plan recorded, and highlight gain and lights applied the same way."""
from __future__ import annotations

import numpy as np
import pytest

from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.bake import BadSetting, ProbeSettings, bake_probe
from gs_ibl_addon.core.bake_batch import bake_probes
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.tolerance import plan_text

ORIGINS = np.array([[0.0, 0.0, 1.5], [0.8, -0.6, 1.0], [-0.7, 0.5, 2.0]])
SUN = synthetic.radiance_functions()["sun"]


@pytest.fixture(scope="module")
def room():
    return synthetic.room_scene().scene


def test_face_size_zero_meets_the_tolerance_at_every_probe(room):
    s = ProbeSettings(irradiance_size=8, tolerance=0.02, max_face_size=256)
    with SplatRenderer(room) as r:
        many = bake_probes(room, ORIGINS, s, renderer=r)
        singles = [bake_probe(room, o, s, renderer=r) for o in ORIGINS]
        gpu_only = bake_probes(None, ORIGINS, s, renderer=r)  # the splats on the GPU alone: the same search
    face = many[0].settings["face_size"]
    # a batch keeps one face size for all its probes (the worst probe decides); a single bake sizes each face
    assert face & (face - 1) == 0 and face <= s.max_face_size
    assert all(p.settings["converged"] and len(p.settings["face_sizes"]) == 6 for p in singles)
    for p, one in zip(many, singles):
        plan = p.settings["tolerance_plan"]
        assert plan["model"] == "change" and plan["met"] and p.settings["converged"]
        assert plan["estimated_error"] <= plan["batch_estimated_error"] <= s.tolerance
        assert plan["face_size"] == face and set(one.settings["tolerance_plan"]) - set(plan) <= {
            "sh_error", "irradiance_between_texels", "face_sizes"}
        assert "faces" in plan_text(p.settings)
    assert [t["face_size"] for t in gpu_only[0].settings["face_size_trials"]] == \
        [t["face_size"] for t in many[0].settings["face_size_trials"]]


def test_irradiance_size_zero_is_refused_before_any_work():
    with pytest.raises(BadSetting, match="irradiance size 0"):
        bake_probes(None, ORIGINS, ProbeSettings(irradiance_size=0), renderer=object())


@pytest.fixture(scope="module")
def shells():
    return {"float": synthetic.shell_scene(SUN, 20000),
            "clipped": synthetic.shell_scene(lambda d: np.minimum(SUN(d), 1.0), 20000)}


@pytest.mark.parametrize("on", ["splats", "cube"])
def test_highlight_gain_is_bake_probes(shells, on):
    s = ProbeSettings(face_size=64, irradiance_size=8, highlight_gain=60.0)
    pos = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, -0.1]])
    scene = shells["clipped"]
    if on == "splats":  # the batch uploads the splats: they are gained first
        many = bake_probes(scene, pos, s)
        singles = [bake_probe(scene, p, s) for p in pos]
    else:  # a renderer holding them: the cube's clipped texels
        with SplatRenderer(scene) as r:
            many = bake_probes(None, pos, s, renderer=r)
            singles = [bake_probe(None, p, s, renderer=r) for p in pos]
    for p, one in zip(many, singles):
        assert p.highlights["on"] == on and p.highlights["gain"] == 60.0
        np.testing.assert_allclose(p.irradiance, one.irradiance, rtol=1e-5, atol=1e-7)
    plain = bake_probes(scene, pos, ProbeSettings(face_size=64, irradiance_size=8))
    assert np.mean(many[0].irradiance) > 1.2 * np.mean(plain[0].irradiance)  # the gain did something


def test_lights_are_split_off_as_bake_probes(shells):
    s = ProbeSettings(face_size=64, irradiance_size=8, lights=1)
    pos = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, -0.1]])
    with SplatRenderer(shells["float"]) as r:
        many = bake_probes(None, pos, s, renderer=r, keep_radiance=False)
        singles = [bake_probe(None, p, s, renderer=r) for p in pos]
    for p, one in zip(many, singles):
        assert len(p.lights) == len(one.lights) == 1 and p.radiance is None
        np.testing.assert_allclose(p.lights[0]["direction"], one.lights[0]["direction"], atol=1e-6)
        np.testing.assert_allclose(p.irradiance, one.irradiance, rtol=1e-5, atol=1e-7)
