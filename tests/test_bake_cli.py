"""The main job end to end without Blender: splat file -> GPU cubemap -> irradiance -> EXR/JSON/PNG files."""
import json
import os

import numpy as np
import pytest

from gs_ibl_addon.cli import main
from gs_ibl_addon.core import cubemap
from gs_ibl_addon.core.bake import RADIANCE_OUT_MAX, ProbeSettings, bake_probe, relative_rms
from gs_ibl_addon.core.formats import read_scene
from gs_ibl_addon.core.formats.ply import write_ply
from gs_ibl_addon.core.image_io import read_exr
from gs_ibl_addon.core.probe import sample_cube_bilinear
from gs_ibl_addon.core.synthetic import SkyGradient, sample_environment, shell_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def sky_shell():
    return shell_scene(SkyGradient(), 6000, radius=5.0)


def test_bake_matches_the_analytic_irradiance(sky_shell):
    sky = SkyGradient()
    normals = cubemap.face_directions(8)
    for method in ("sh", "exact", "conv", "auto"):
        r = bake_probe(sky_shell, [0, 0, 0], ProbeSettings(method=method, face_size=32, irradiance_size=8))
        got = sample_cube_bilinear(r.irradiance, normals)
        want = sky.irradiance_over_pi(normals)
        # 1%: the shell shows the sky blurred over one splat spacing, which moves irradiance by well under 1%
        assert relative_rms(got, want) < 0.01, (method, relative_rms(got, want))
        assert r.hole_fraction < 1e-3
        assert r.settings["stage_devices"]["irradiance"] == "gpu"


def test_auto_face_size_stops_when_the_irradiance_has_converged():
    # a small very bright patch needs bigger faces than the smooth sky; auto must find out by itself
    from gs_ibl_addon.core.synthetic import radiance_functions
    sky = bake_probe(shell_scene(SkyGradient(), 6000, radius=5.0), [0, 0, 0],
                     ProbeSettings(tolerance=0.01, irradiance_size=8, max_face_size=256))
    sun = bake_probe(shell_scene(radiance_functions()["sun"], 8000, radius=5.0), [0, 0, 0],
                     ProbeSettings(tolerance=0.01, irradiance_size=8, max_face_size=256))
    for r in (sky, sun):
        trials = r.settings["face_size_trials"]  # 32, 64, then where the error estimate says (core/tolerance.py)
        faces = [t["face_size"] for t in trials]
        assert faces[:2] == [32, 64] and faces == sorted(faces) and all(f & (f - 1) == 0 for f in faces)
        assert r.settings["face_size"] == min(trials[-1]["face_size"], RADIANCE_OUT_MAX)  # per-face: the cube written
        if r.settings["converged"]:
            assert trials[-1]["estimate"] <= 0.01
    assert sky.settings["converged"] and sky.settings["face_size"] <= 64
    assert sun.settings["face_size"] >= sky.settings["face_size"]


def test_glossy_bake_adds_ggx_levels(sky_shell):
    r = bake_probe(sky_shell, [0, 0, 0], ProbeSettings(face_size=32, irradiance_size=8, glossy=True))
    assert len(r.prefiltered) == len(r.roughness) >= 4 and r.roughness[0] == 0.0
    # roughness 0 is the radiance itself; the roughest level of a smooth sky is close to its irradiance
    np.testing.assert_allclose(r.prefiltered[0], r.radiance[..., :3], atol=1e-5)
    rough = sample_cube_bilinear(r.prefiltered[-1], cubemap.face_directions(8))
    irr = sample_cube_bilinear(r.irradiance, cubemap.face_directions(8))
    assert relative_rms(rough, irr) < 0.1
    assert r.timings_ms["ggx"] > 0


def test_bake_command_writes_the_files(tmp_path, sky_shell, capsys):
    ply = tmp_path / "sky.ply"
    write_ply(ply, sky_shell)
    out = tmp_path / "probe"
    assert main(["bake", str(ply), "--probe", "0", "0", "0", "--face-size", "32", "--out", str(out)]) == 0
    names = set(os.listdir(out))
    assert {"radiance.exr", "irradiance.exr", "probe.json", "preview.png"} <= names
    meta = json.loads((out / "probe.json").read_text())
    assert meta["splat_count"] == sky_shell.count and len(meta["sh_coefficients"]) == 9
    irr = read_exr(out / "irradiance.exr")
    # lat-long row 0 looks up (+Z): a + 2/3 b; the bottom row looks down: a - 2/3 b
    sky = SkyGradient()
    np.testing.assert_allclose(irr[0].mean(0), np.add(sky.a, np.multiply(2 / 3, sky.b)), rtol=0.02)
    np.testing.assert_allclose(irr[-1].mean(0), np.subtract(sky.a, np.multiply(2 / 3, sky.b)), rtol=0.02)


def test_bad_input_is_one_clear_line(tmp_path, capsys):
    bad = tmp_path / "broken.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nend_header\n")
    assert main(["bake", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "broken.ply" in err and "Traceback" not in err
    assert main(["bake", str(tmp_path / "missing.ply"), "--out", str(tmp_path / "o")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_render_and_cubemap_commands(tmp_path):
    ply = tmp_path / "room.ply"
    assert main(["sample", str(ply)]) == 0
    assert main(["render", str(ply), "--camera", "0", "-2", "1.5", "--look-at", "0", "2", "1", "--size", "64", "48",
                 "--out", str(tmp_path / "v.exr"), "--png", str(tmp_path / "v.png"), "--depth", str(tmp_path / "z.exr")]) == 0
    img = read_exr(tmp_path / "v.exr")
    assert img.shape == (48, 64, 4) and img[..., 3].min() > 0.99  # inside a closed room every pixel is covered
    z = read_exr(tmp_path / "z.exr")[..., 0]
    assert z.shape == (48, 64) and 0.5 < z.min() and z.max() < 10  # the room's walls, a few metres away
    assert main(["cubemap", str(ply), "--probe", "0", "0", "1.5", "--face-size", "16", "--out", str(tmp_path / "c")]) == 0
    assert len([f for f in os.listdir(tmp_path / "c") if f.startswith("face_")]) == 6


def test_bundled_sample_is_the_generated_one():
    # samples/room.ply must not drift from the generator (python -m gs_ibl_addon sample samples/room.ply)
    bundled = read_scene(os.path.join(ROOT, "samples", "room.ply"))
    fresh = sample_environment().with_sh_degree(0)
    assert bundled.count == fresh.count
    np.testing.assert_allclose(bundled.positions, fresh.positions, atol=1e-6)
    np.testing.assert_allclose(bundled.sh, fresh.sh, atol=1e-5)


@pytest.mark.parametrize("args", [
    ["render", "X", "--camera", "0", "0", "0", "--look-at", "1", "0", "0", "--size", "0", "48", "--out", "o.exr"],
    ["cubemap", "X", "--probe", "0", "0", "0", "--face-size", "0", "--out", "o"],
    ["bake", "X", "--face-size", "-4", "--out", "o"],
    ["bake", "X", "--irradiance-size", "-1", "--out", "o"],
])
def test_bad_sizes_are_refused_before_any_work(args, capsys):
    with pytest.raises(SystemExit) as e:
        main(args)
    assert e.value.code == 2
    assert "must be 1 or more" in capsys.readouterr().err


def test_convert_refuses_an_unknown_output_before_reading(tmp_path, capsys):
    assert main(["convert", str(tmp_path / "does-not-exist.ply"), str(tmp_path / "out.obj")]) == 2
    err = capsys.readouterr().err
    assert "cannot write '.obj'" in err and "no such file" not in err


@pytest.mark.parametrize("ext,dropped", [(".sog", "bands 1-3"), (".splat", "bands 1-3"), (".ksplat", "band 3"),
                                         (".spz", None), (".glb", None), (".ply", None)])
def test_convert_says_which_sh_bands_a_format_drops(tmp_path, capsys, ext, dropped):
    from gs_ibl_addon.core.synthetic import random_scene
    src = tmp_path / "in.ply"
    write_ply(src, random_scene(200, sh_degree=3))
    capsys.readouterr()
    assert main(["convert", str(src), str(tmp_path / f"out{ext}")]) == 0
    err = capsys.readouterr().err
    if dropped:
        assert f"SH {dropped} (view-dependent colour) were dropped" in err and ".ply, .spz, .glb keep them" in err
    else:
        assert "dropped" not in err


def test_core_refuses_bad_sizes():
    from gs_ibl_addon.core.render.views import ViewBatch
    with pytest.raises(ValueError, match="face size 0"):
        ViewBatch.cubemap([0, 0, 0], 0)
    with pytest.raises(ValueError, match="image size"):
        ViewBatch.pinhole([0, 0, 0], [1, 0, 0], 60, 0, 10)
    with pytest.raises(ValueError, match="irradiance size"):
        bake_probe(shell_scene(SkyGradient(), 500), [0, 0, 0], ProbeSettings(irradiance_size=-1))


def test_bake_from_a_renderer_alone_matches_bake_from_the_scene(sky_shell):
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    settings = ProbeSettings(face_size=32, irradiance_size=8)
    a = bake_probe(sky_shell, [0, 0, 0], settings)
    b = bake_probe(None, [0, 0, 0], settings, renderer=SplatRenderer(sky_shell))
    np.testing.assert_array_equal(a.irradiance, b.irradiance)
    assert b.splat_count == sky_shell.count
    with pytest.raises(ValueError, match="needs both a renderer"):
        bake_probe(None, None, settings, renderer=SplatRenderer(sky_shell))


def _bake_args(ply, out, *extra):
    return ["bake", str(ply), "--probe", "0", "0", "0", "--face-size", "16", "--irradiance-size", "4",
            "--out", str(out), *extra]


def test_rebake_removes_the_earlier_bakes_files_and_nothing_else(tmp_path, sky_shell):
    ply = tmp_path / "sky.ply"
    write_ply(ply, sky_shell)
    out = tmp_path / "probe"
    assert main(_bake_args(ply, out, "--glossy", "--faces")) == 0
    assert (out / "ggx_0.exr").exists() and (out / "faces").is_dir()
    (out / "notes.txt").write_text("the user's own file")
    assert main(_bake_args(ply, out)) == 0
    names = sorted(os.listdir(out))
    assert names == ["irradiance.exr", "notes.txt", "preview.png", "probe.json", "radiance.exr"], names
    assert json.loads((out / "probe.json").read_text())["files"] == ["irradiance.exr", "preview.png", "radiance.exr"]


def test_a_failed_write_leaves_the_earlier_bake_whole(tmp_path, sky_shell, monkeypatch, capsys):
    import gs_ibl_addon.core.probe.result as result_module
    ply = tmp_path / "sky.ply"
    write_ply(ply, sky_shell)
    out = tmp_path / "probe"
    assert main(_bake_args(ply, out)) == 0
    before = {n: (out / n).read_bytes() for n in os.listdir(out)}
    calls = []

    def failing_write(path, image, half=False):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(28, "No space left on device", path)
        return real_write(path, image, half=half)

    real_write = result_module.write_exr
    monkeypatch.setattr(result_module, "write_exr", failing_write)
    assert main(_bake_args(ply, out, "--glossy")) == 2
    assert "No space left" in capsys.readouterr().err
    assert {n: (out / n).read_bytes() for n in os.listdir(out)} == before  # old bake intact, nothing partial


def test_out_of_memory_becomes_advice(sky_shell, monkeypatch):
    from gs_ibl_addon.core.render import renderer as renderer_module

    def no_memory(self, batch, *args, **kwargs):
        raise MemoryError("cannot allocate 4096.0 MiB for buffer 'image'")

    monkeypatch.setattr(renderer_module.SplatRenderer, "render", no_memory)
    with pytest.raises(MemoryError, match="smaller face size"):
        bake_probe(sky_shell, [0, 0, 0], ProbeSettings(face_size=32, irradiance_size=4))


def test_big_faces_render_one_at_a_time_with_progress_and_the_same_result(sky_shell, monkeypatch):
    import gs_ibl_addon.core.bake as bake_module
    settings = ProbeSettings(face_size=32, irradiance_size=4)
    whole = bake_probe(sky_shell, [0, 0, 0], settings)
    monkeypatch.setattr(bake_module, "FACE_BY_FACE_FROM", 32)
    said = []
    split = bake_probe(sky_shell, [0, 0, 0], settings, progress=lambda msg, frac: said.append((msg, frac)))
    assert [m for m, _ in said if m.startswith("rendering face")] == [f"rendering face {f} of 6 (32x32)"
                                                                     for f in range(1, 7)]
    assert [f for _, f in said] == sorted(f for _, f in said)
    # one face has fewer tiles than six, so its tile lists may be split into other chunks: the same sums in another
    # order (renderer.raster_chunks; tests/test_multi_probe.py allows 2e-4 for it)
    np.testing.assert_allclose(split.radiance, whole.radiance, atol=2e-4)


def test_nan_probe_is_refused_by_the_core_too(sky_shell):
    from gs_ibl_addon.core.bake import BadSetting
    with pytest.raises(BadSetting, match="not finite"):
        bake_probe(sky_shell, [np.nan, 0, 1], ProbeSettings(face_size=16))
