"""Blender 5.3's native splats as a probe's source, in the bpy 5.3 root (Python 3.13), with the built zip installed
by Blender's own installer as the matrix does (test_matrix.py): Blender's PLY and SPZ importers make the Point
Clouds, tests/real_blender/native_splats.py bakes from them with the installed extension, and here the irradiance
is compared with our core bake of the same file in the sRGB colour space (Blender's rule).

Skipped unless the trixie root is made (`scripts/blender_roots.sh ensure trixie`; scripts/test_real_blender.sh).
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import test_matrix as matrix  # noqa: E402 (the matrix's runner, installer and roots)

REPO = matrix.REPO
OUT = matrix.OUT / "native-5.3"
ENTRY = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
IRRADIANCE_RTOL = 0.01  # the bar: our bake from Blender's splats = our core bake of the file, within 1%


def _inputs(folder: Path) -> dict[str, tuple[Path, str]]:
    """The files Blender imports: the guitar capture as plain PLY and as SPZ (our convert), and a small SH-degree-3
    scene (random colours read as sRGB) that checks the radiance:sh_* order."""
    from gs_ibl_addon.core.formats.ply import write_ply
    from gs_ibl_addon.core.synthetic import random_scene
    files = {"guitar_ply": (folder / "guitar.ply", "ply"), "guitar_spz": (folder / "guitar.spz", "spz"),
             "sh3_ply": (folder / "sh3.ply", "ply")}
    for key in ("guitar_ply", "guitar_spz"):
        subprocess.run([sys.executable, "-m", "gs_ibl_addon", "convert", str(matrix.CAPTURE), str(files[key][0])],
                       cwd=REPO, check=True, capture_output=True, text=True)
    sh3 = random_scene(3000, seed=5, sh_degree=3, extent=2.0)
    sh3.colour_space = "srgb"  # as a capture from outside: the file declares nothing
    write_ply(files["sh3_ply"][0], sh3)
    return files


def _similarity(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, float]:
    """The 4x4 rotation + translation taking points src to dst (least squares), and the largest residual."""
    a, b = src.astype(np.float64), dst.astype(np.float64)
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    r = (u @ vt).T
    if np.linalg.det(r) < 0:
        raise AssertionError("Blender's importer mirrors the splats relative to our reader")
    m = np.identity(4)
    m[:3, :3], m[:3, 3] = r, cb - r @ ca
    return m, float(np.abs(a @ r.T + m[:3, 3] - b).max())


def test_bake_from_blenders_native_splats(tmp_path):
    matrix.require_root(ENTRY.root)
    from gs_ibl_addon.core.bake import ProbeSettings, bake_probe
    from gs_ibl_addon.core.formats import read_scene
    OUT.mkdir(parents=True, exist_ok=True)
    runner = matrix.Runner(ENTRY, tmp_path)
    try:
        files = _inputs(tmp_path)
        args = {"work": str(runner.inner),
                "files": [[k, str(runner.inner / p.name), kind] for k, (p, kind) in files.items()]}
        for p, _ in files.values():
            shutil.copy(p, runner.host / p.name)
        result = matrix.run_script(runner, HERE / "native_splats.py", args, "GSIBL-NATIVE-RESULT", "native")
        for key, (path, _kind) in files.items():
            rec = result["files"][key]
            assert rec.get("ok"), f"{key}: {rec.get('error')}"
            assert rec["native"] and rec["splat_object"] and rec["data_type"] == "GAUSSIAN_SPLAT", rec
            assert rec["colour_space"] == "srgb" and rec["probe_colour_space"] == "srgb" and rec["world_is_ours"]
            assert rec["muted"] == [True, False, False], rec["muted"]  # seen by the camera, not by bounces
            assert rec["restored"] == [True, True, True], rec["restored"]
            assert rec["auto"] == [1, 1], f"{key}: Update When Moved after moving the native object: {rec['auto']}"
            got = np.load(runner.host / f"{key}.npz")
            ours = read_scene(path)
            assert ours.colour_space == "srgb" and len(got["positions"]) == ours.count
            m, residual = _similarity(ours.positions, got["positions"])
            assert residual < 1e-3, f"{key}: Blender's splat centres are not ours moved rigidly ({residual:.2e})"
            # SH as Blender stores them (radiance:base + radiance:sh_k) are the file's, in 3DGS order
            tol = 1e-6 if key.endswith("ply") else 0.02  # SPZ: both decoders of the same quantised bytes
            np.testing.assert_allclose(got["sh"], ours.sh, atol=tol, err_msg=f"{key}: SH")
            np.testing.assert_allclose(got["opacities"], ours.opacities, atol=tol if tol > 1e-6 else 1e-5)
            if key.startswith("guitar"):
                core = bake_probe(ours.transformed(m), np.array(rec["probe"]),
                                  ProbeSettings(method="exact", face_size=64, irradiance_size=16))
                want, irr = np.asarray(core.irradiance)[..., :3], got["irradiance"][..., :3]
                rel = float(np.sqrt(np.mean((irr - want) ** 2) / np.mean(want ** 2)))
                print(f"\n[native 5.3] {key}: {len(got['positions']):,} splats, import {rec['import_s']:.2f} s, "
                      f"bake {rec['bake_s']:.1f} s, irradiance vs core bake (srgb): rel. RMS {rel:.2e}; "
                      f"linear/srgb light {rec['linear_over_srgb']:.2f}")
                assert rel < IRRADIANCE_RTOL, f"{key}: irradiance differs from the core bake by {rel:.2%}"
                assert rec["linear_over_srgb"] > 1.2  # the rule changes the light (sRGB mid-tones are darker)
    finally:
        keep = OUT / "run"
        shutil.rmtree(keep, ignore_errors=True)
        shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.spz", "*.zip", "*.npz"))
        runner.close()
