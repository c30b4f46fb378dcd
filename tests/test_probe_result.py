"""Lat-long resampling (Blender mapping), SH lat-long irradiance, and the files write_probe produces."""
import json

import numpy as np
import pytest

from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.image_io import read_exr
from gs_ibl_addon.core.probe import (cube_to_latlong, exact_irradiance, filter_probe, sh_irradiance_latlong,
                                     write_probe)
from gs_ibl_addon.core.probe.reference import cube_from_function, smooth_environment


def test_latlong_follows_blender_mapping():
    # A cube that is 1 only around +Y: in Blender's lat-long the +Y direction is u = 0.25 at the equator.
    cube = cube_from_function(lambda d: np.repeat(np.maximum(d[..., 1:2], 0) ** 8, 3, -1), 32)
    img = cube_to_latlong(cube, 64)
    assert img.shape == (32, 64, 3)
    row, col = np.unravel_index(np.argmax(img[..., 0]), img.shape[:2])
    assert col in (15, 16) and row in (15, 16)  # u = (col + 0.5) / 64 ~ 0.25, v ~ 0.5


def test_latlong_resample_error_on_smooth_environment():
    # Bilinear within faces of a 32^2 cube: measured max abs error 3.5e-3 on values 0.2..2.5: tolerance 1e-2.
    cube = cube_from_function(smooth_environment, 32)
    img = cube_to_latlong(cube, 128)
    want = smooth_environment(cubemap.latlong_directions(128, 64))
    np.testing.assert_allclose(img, want, atol=1e-2)


@pytest.mark.parametrize("n,width,height", [(1, 8, None), (3, 50, 17), (16, 64, None), (32, 130, 64), (3, 400, 170)])
def test_latlong_tap_table_is_the_lookup(n, width, height):
    # The cached tap table must read exactly what the per-direction seamless lookup reads, corners included
    # (n = 1 and 3 put lat-long texels on cube corners: the table splits those taps in three; 400 x 170 is built
    # in several chunks).
    from gs_ibl_addon.core.probe.latlong import cube_to_latlong_reference, latlong_taps
    cube = np.random.default_rng(n).random((6, n, n, 4)) * 10.0 ** np.random.default_rng(1).normal(0, 2, (6, n, n, 1))
    np.testing.assert_allclose(cube_to_latlong(cube, width, height), cube_to_latlong_reference(cube, width, height),
                               rtol=1e-12)
    if n in (1, 3):
        assert len(latlong_taps(n, width, height or width // 2).corner_rows) > 0


def test_sh_latlong_irradiance_matches_exact():
    # Order-2 SH evaluated per lat-long texel vs exact integration of the cube: 1% relative RMS (brief).
    cube = cube_from_function(smooth_environment, 32)
    res = filter_probe(cube, irradiance_size=8, method="sh", roughness=None)
    img = sh_irradiance_latlong(res.sh_coefficients, 32)
    ref = exact_irradiance(cube, cubemap.latlong_directions(32, 16))
    assert np.sqrt(np.mean((img - ref) ** 2)) / np.sqrt(np.mean(ref ** 2)) < 0.01


@pytest.mark.parametrize("half", [False, True])
def test_write_probe_files(tmp_path, half):
    cube = np.concatenate([cube_from_function(smooth_environment, 16), np.ones((6, 16, 16, 1))], -1)
    cube[5, :, :, :] = 0.0  # -Z has no splats
    res = filter_probe(cube, irradiance_size=8, method="sh", roughness=(0.0, 0.5), ggx_samples=32,
                       splat_count=1234, device="test cpu")
    written = write_probe(res, tmp_path, half=half, cube_faces=True)
    rad = read_exr(tmp_path / "radiance.exr")
    assert rad.shape == (32, 64, 3)
    irr = read_exr(tmp_path / "irradiance.exr")
    assert irr.shape == (32, 64, 3) and np.all(irr >= 0)
    assert read_exr(tmp_path / "ggx_1.exr").shape[2] == 3
    face = read_exr(tmp_path / "faces" / "irradiance_posz.exr")
    np.testing.assert_allclose(face, res.irradiance[4], rtol=1e-3 if half else 1e-6)
    meta = json.loads((tmp_path / "probe.json").read_text())
    assert meta["splat_count"] == 1234 and meta["device"] == "test cpu"
    assert meta["hole_fraction"] == pytest.approx(1 / 6)
    assert np.array(meta["sh_coefficients"]).shape == (9, 3) and meta["sh_order"] == 2
    assert set(meta["timings_ms"]) >= {"sh_project", "irradiance", "ggx"}
    assert "E(n)/pi" in meta["conventions"]["irradiance"]
    assert meta["roughness"] == [0.0, 0.5]
    assert sorted(meta["files"]) == sorted(k for k in written if k != "probe.json")


def test_filter_probe_rejects_bad_input():
    with pytest.raises(ValueError, match="method"):
        filter_probe(np.ones((6, 4, 4, 3)), method="magic")
    with pytest.raises(ValueError, match=r"\(6, N, N, C\)"):
        filter_probe(np.ones((5, 4, 4, 3)))
    bad = np.ones((6, 4, 4, 3))
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        filter_probe(bad)
