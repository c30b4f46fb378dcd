"""Where the light volume stands and how dense (core/probe/volume_region.py): the box over the lit boxes, the
budget's refusal (before work, naming what fits) or coarsening (said), and the spacing measured from the light."""
import numpy as np
import pytest

from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.probe import volume as vol
from gs_ibl_addon.core.probe import volume_region as vreg
from gs_ibl_addon.core.probe.grid import GridSpec

BOXES = [((0.0, 0.0, 0.0), (0.5, 0.5, 0.5)), ((2.0, 1.0, 0.2), (2.4, 1.3, 1.0))]  # a mesh at two frames, or two


def test_the_region_spans_every_box_with_its_margin():
    lo, hi = vreg.region_box(BOXES, margin=0.1)
    assert np.allclose(lo, [-0.1, -0.1, -0.1]) and np.allclose(hi, [2.5, 1.4, 1.1])
    lo, hi = vreg.region_box(BOXES, margin=0.1, within=((0.0, 0.0, 0.0), (2.0, 2.0, 2.0)))
    assert np.allclose(lo, 0.0) and np.allclose(hi, [2.0, 1.4, 1.1])
    with pytest.raises(ValueError, match="no lit mesh"):
        vreg.region_box([])
    with pytest.raises(ValueError, match="outside the splats"):
        vreg.region_box(BOXES, within=((5.0, 5.0, 5.0), (6.0, 6.0, 6.0)))
    with pytest.raises(ValueError, match="finite"):
        vreg.region_box([((0, 0, np.nan), (1, 1, 1))])


def test_a_plan_within_the_budget():
    plan = vreg.plan_volume(BOXES, 0.5, margin=0.1)
    assert plan.spec.shape == (7, 4, 4) and plan.spacing == 0.5  # 2.6 x 1.5 x 1.2 m
    step = (np.subtract(plan.spec.hi, plan.spec.lo)) / (np.array(plan.spec.shape) - 1)
    assert np.all(step <= 0.5 + 1e-9)
    assert "112 probes" in plan.messages[-1]
    # the spacings the grid has, not the one asked for (each axis rounds its node count up): the same words as
    # Blender's report
    words = f"{step.min():.2f}-{step.max():.2f} m apart"
    assert plan.messages[-1].endswith(words) and vol.spacing_words(plan.spec) == words
    assert vol.spacing_words(GridSpec((0, 0, 0), (1, 1, 1), (3, 3, 3))) == "0.50 m apart"


def test_too_large_is_refused_before_work_with_what_fits():
    with pytest.raises(vreg.VolumeTooLarge) as e:
        vreg.plan_volume(BOXES, 0.1, budget=200, margin=0.1)
    msg = str(e.value)
    assert "over the budget of 200" in msg and "spacing of" in msg and "a side" in msg
    # the spacing it names fits
    fits = float(msg.split("spacing of ")[1].split(" m")[0])
    assert vreg.plan_volume(BOXES, fits + 0.005, budget=200, margin=0.1).spec.count <= 200


def test_too_large_is_coarsened_and_said():
    plan = vreg.plan_volume(BOXES, 0.1, budget=200, margin=0.1, coarsen=True)
    assert plan.spec.count <= 200 and plan.spacing > 0.1
    assert "coarsened from 0.10 m" in plan.messages[0]


def test_the_spacing_follows_the_light():
    """A volume whose light doubles over 1 m along x: 10% of change is ~0.1 m of it (clamped at MIN_SPACING); a
    uniform light keeps the coarse spacing."""
    spec = GridSpec((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (3, 3, 3))
    ramp = vol.synthetic_volume(spec, lambda p, n: (1.0 + p[..., :1]) * np.ones(3))
    g = vreg.light_gradient(ramp)
    assert g.max() == pytest.approx(0.5 / 1.25 / 0.5)  # the first x pair: 1.0 -> 1.5 over 0.5 m, mean 1.25
    assert vreg.spacing_from_light(ramp, 0.1) == pytest.approx(max(vreg.MIN_SPACING, 0.1 / np.quantile(g, 0.9)))
    flat = vol.synthetic_volume(spec, lambda p, n: 0.3 * np.ones(p.shape))
    assert vreg.spacing_from_light(flat, 0.1) == pytest.approx(0.5)


def test_choose_volume_measures_then_plans():
    """A shell of one colour: the light is uniform, so the plan keeps the coarse spacing; the coarse volume comes
    back for reuse."""
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    scene = synthetic.shell_scene(lambda d: np.tile([0.5, 0.4, 0.3], (len(d), 1)), 8000, radius=3.0)
    with SplatRenderer(scene) as r:
        plan, coarse = vreg.choose_volume(r, [((-0.4, -0.4, -0.4), (0.4, 0.4, 0.4))], tolerance=0.1, budget=27)
    assert coarse.spec.count <= 27 and plan.spec.count <= 27
    assert "light changes 10% over" in plan.messages[0]
    assert plan.spacing == pytest.approx(vol.spec_spacing(coarse.spec))  # uniform light: the coarse spacing kept
