"""The command line's preview PNG: three panels, the holes outlined, one exposure for all."""
import numpy as np

from gs_ibl_addon.core.preview import PANEL_HEIGHT, outline, preview_panels, write_preview
from gs_ibl_addon.core.probe import ProbeResult
from gs_ibl_addon.core.probe.reference import cube_from_function, smooth_environment


def _result(holes: bool) -> ProbeResult:
    rad = cube_from_function(smooth_environment, 16)
    rad = np.concatenate([rad, np.ones(rad.shape[:3] + (1,))], -1)
    if holes:
        rad[2, 4:12, 4:12, 3] = 0.0  # a square hole in the middle of the +Y face
    irr = cube_from_function(smooth_environment, 8)
    return ProbeResult(radiance=rad, irradiance=irr, hole_fraction=0.02 if holes else 0.0,
                       hole_fill={"method": "mean"}, splat_count=10, device="test")


def test_outline_is_the_border_of_the_mask_and_wraps():
    m = np.zeros((6, 8), bool)
    m[2:5, 0:3] = True
    edge = outline(m)
    assert edge[2:5, 0:3].sum() == 8 and not edge[3, 1]  # the ring of a 3x3 square, not its centre
    assert not edge[~m].any()
    assert not outline(np.ones((4, 8), bool))[1:3].any()  # a band all the way round has no left or right edge


def test_panels_outline_holes_in_magenta_only_with_holes():
    for holes in (False, True):
        panels, exposure = preview_panels(_result(holes))
        assert [p.shape for p, _ in panels] == [(PANEL_HEIGHT, 2 * PANEL_HEIGHT, 3)] * 2 + [(PANEL_HEIGHT,) * 2 + (3,)]
        assert np.isfinite(exposure) and all(0 <= p.min() and p.max() <= 1 for p, _ in panels)
        magenta = np.all(panels[0][0] == (1.0, 0.0, 1.0), -1)
        assert magenta.any() == holes and ("magenta" in panels[0][1]) == holes


def test_write_preview_png(tmp_path):
    import OpenImageIO as oiio
    path = tmp_path / "preview.png"
    write_preview(_result(True), path, title="scene.ply")
    spec = oiio.ImageInput.open(str(path)).spec()
    assert spec.width > 5 * PANEL_HEIGHT and spec.height > PANEL_HEIGHT and spec.nchannels == 3
