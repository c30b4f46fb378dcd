"""Blender's Cycles as the outside reference for our light (issue 16, part 4), in the bpy 5.3 root with the built zip
installed by Blender's own installer (tests/real_blender/cycles_reference.py does the Blender side).

The scene: a closed shell of splats (radius SHELL_R, shuffled order) whose colour seen from its centre is a smooth
function of direction, and a small white diffuse sphere at the centre; the World is black, so the sphere is lit only
by the splats, which Blender's own PLY importer made into a native Gaussian-splat Point Cloud.

(a) Cycles path-traces the sphere (denoiser off, fixed samples); we predict it from our bake of a probe at the
    sphere's centre: a white Lambertian surface of albedo a shows a * E(n)/pi, read from our irradiance cube along
    each pixel's surface normal (analytic: the sphere and camera are known). Compared over blocks of the sphere's
    visible face, per channel, within SPHERE_RTOL. Also: the same sphere lit by our World in Cycles (the extension's
    bake inside Blender, splats' bounces muted) against the native render.
(b) Our pinhole render (core ViewBatch.pinhole) of the same splats against Cycles' camera view of them: mean per-pixel
    difference and coverage within VIEW_RTOL and COVERAGE_TOL.

Two colour spaces:
  * srgb: the shell stores c = SH + 0.5 in [0.1, 0.95] and both Blender and our bake (colour space sRGB) decode
    radiance = srgb_to_linear(c).
  * linear: the scene's radiance L = c is linear and HDR (up to ~2.4). Blender decodes every splat as sRGB, so the
    file Blender imports stores c' = linear_to_srgb_extended(L) (core/colour.py: the exact inverse of Blender's curve,
    unclamped above 1), and Blender's decode gives back L; our bake reads the linear scene with the Linear rule.

Sizes are kept small for a 2-core CI machine; the test prints the tolerances, the measured numbers and render times.
Skipped unless the trixie root is made (`scripts/blender_roots.sh ensure trixie`; scripts/test_real_blender.sh).
"""
from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import blender_scene as bs  # noqa: E402 (the scenes and Blender set-up shared with the benchmarks)
import test_matrix as matrix  # noqa: E402 (the matrix's runner, installer and roots)

REPO = matrix.REPO
OUT = matrix.OUT / "cycles-reference"
ENTRY = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")

SHELL_R = 10.0
SHELL_SPLATS = 6000
# sphere radius / shell radius = 0.25%: the one probe at the sphere's centre misses the light's change across the
# sphere (parallax) by at most ~0.45% here (0.9% at 0.5%, in the sRGB case's darkest channel)
SPHERE = {"centre": [0.0, 0.0, 0.0], "radius": 0.025}
SPHERE_CAMERA = {"position": [0.03, -0.095, 0.025], "look_at": SPHERE["centre"], "fov_deg": 32.0}
VIEW_CAMERA = {"position": [0.0, 0.0, 0.0], "look_at": [3.0, -4.0, 2.0], "fov_deg": 60.0}
SPHERE_SIZE = 40  # pixels square; the sphere covers ~60% of them
VIEW_SIZE = (48, 32)
SAMPLES = int(os.environ.get("GS_IBL_CYCLES_SAMPLES", 1024))  # Cycles spp for the sphere (noise printed)
VIEW_SAMPLES = 64
WORLD_SAMPLES = 256
ALBEDO = 0.8
BLOCKS = 3  # the sphere's face split into BLOCKS x BLOCKS screen blocks, each compared on its own
SPHERE_RTOL = 0.02  # the issue's bar: Cycles' native render = our bake's prediction within 2%
# mean |ours - Cycles| over the mean radiance of the camera view: ours blends a camera view in 3DGS's order (depth
# along the view axis, as captures are trained and their viewers draw them), Cycles each ray's hits in the order
# it meets them: measured 2.3-3.6% on 2026-12-05 (1.2-1.8% while camera views were sorted by distance)
VIEW_RTOL = 0.045
COVERAGE_TOL = 0.01  # mean |alpha ours - alpha Cycles|
CAPTURE_SIZE = (80, 128)  # the guitar capture's front view (tests/test_render_real_capture.py's, twice as fine)
CAPTURE_SAMPLES = 64
# A real capture differs more (docs/blender.md, "Cycles as the outside reference"): most of its splats are smaller
# than a pixel here, and our anti-aliasing spreads them over more than a pixel's box; at 4x the resolution the
# coverage gap falls from 16% to 6.5% and the mean colour agrees within 1.5%. Measured at this size: mean colour
# -1.5/+0.5/+8.5% (RGB), coverage 0.016, per-pixel mean |difference| 31% (Cycles' 64 spp noise included).
CAPTURE_MEAN_RTOL = 0.10  # per channel, the image's mean colour
CAPTURE_RTOL = 0.40  # per-pixel mean |ours - Cycles| over the mean, over covered pixels
CAPTURE_COVERAGE_TOL = 0.02  # mean |alpha ours - alpha Cycles|


def capture_camera(scene) -> dict:
    """The guitar's front view (the capture is Y-down; its front faces +X)."""
    lo, hi = scene.bounds()
    centre = (lo + hi) / 2
    return {"position": (centre + np.array([1.2 * np.linalg.norm(hi - lo), 0, 0])).tolist(),
            "look_at": centre.tolist(), "fov_deg": 40.0, "up": [0.0, -1.0, 0.0]}


def _radiance(d: np.ndarray) -> np.ndarray:
    from gs_ibl_addon.core.synthetic import ColouredWalls
    return ColouredWalls(power=2.0)(d)  # smooth: a colour toward each axis, blended


def shell(space: str):
    """The case's scene as our bake reads it, and the one Blender imports (its stored colour encoded for sRGB)."""
    from gs_ibl_addon.core.colour import linear_sh_for_srgb_rule
    from gs_ibl_addon.core.synthetic import shell_scene
    fn = _radiance if space == "srgb" else (lambda d: 2.5 * _radiance(d))  # linear: HDR, above 1 in places
    ours = shell_scene(fn, SHELL_SPLATS, radius=SHELL_R)
    ours.colour_space = space
    blender = shell_scene(fn, SHELL_SPLATS, radius=SHELL_R)
    if space == "linear":
        blender.sh = linear_sh_for_srgb_rule(blender.sh)
    blender.colour_space = "srgb"  # what Blender does with any splat: the file declares nothing
    return ours, blender


@pytest.fixture(scope="module")
def cycles_run(tmp_path_factory):
    matrix.require_root(ENTRY.root)
    from gs_ibl_addon.core.formats.ply import write_ply
    OUT.mkdir(parents=True, exist_ok=True)
    runner = matrix.Runner(ENTRY, tmp_path_factory.mktemp("cycles"))
    try:
        cases = []
        for space in ("srgb", "linear"):
            _, blender = shell(space)
            write_ply(runner.host / f"shell_{space}.ply", blender)
            cases.append({"key": space, "ply": str(runner.inner / f"shell_{space}.ply"), "colour_space": "srgb"})
        from gs_ibl_addon.core.formats import read_scene
        subprocess.run([sys.executable, "-m", "gs_ibl_addon", "convert", str(matrix.CAPTURE),
                        str(runner.host / "guitar.ply")], cwd=REPO, check=True, capture_output=True, text=True)
        captures = [{"key": "guitar", "ply": str(runner.inner / "guitar.ply"), "size": list(CAPTURE_SIZE),
                     "samples": CAPTURE_SAMPLES, "camera": capture_camera(read_scene(runner.host / "guitar.ply"))}]
        shutil.copy(runner.host / "guitar.ply", OUT / "guitar.ply")  # our render reads the same file
        args = {"work": str(runner.inner), "cases": cases, "sphere": SPHERE, "sphere_camera": SPHERE_CAMERA,
                "view_camera": VIEW_CAMERA, "size": [SPHERE_SIZE, SPHERE_SIZE], "view_size": list(VIEW_SIZE),
                "samples": SAMPLES, "view_samples": VIEW_SAMPLES, "world_samples": WORLD_SAMPLES,
                "albedo": ALBEDO, "face_size": 64, "threads": 2, "captures": captures}
        result = matrix.run_script(runner, HERE / "cycles_reference.py", args, "GSIBL-CYCLES-RESULT", "cycles")
        arrays = {p.stem: np.load(p) for p in runner.host.glob("*.npy")}
        yield result, arrays
    finally:
        keep = OUT / "run"
        shutil.rmtree(keep, ignore_errors=True)
        shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.zip"))
        runner.close()


@pytest.mark.parametrize("space", ["srgb", "linear"])
def test_cycles_sphere_lit_by_native_splats_matches_our_bake(cycles_run, space):
    from gs_ibl_addon.core.bake import ProbeSettings, bake_probe
    from gs_ibl_addon.core.probe.sampling import sample_cube_bilinear
    result, arrays = cycles_run
    rec = result["cases"][space]
    assert rec.get("ok"), rec.get("error")
    assert rec["native"] and rec["count"] == SHELL_SPLATS
    ours, _ = shell(space)
    core = bake_probe(ours, np.array(SPHERE["centre"]), ProbeSettings(method="exact", face_size=64,
                                                                        irradiance_size=16))
    irr = np.asarray(core.irradiance)[..., :3]
    # the extension's bake inside Blender, from Blender's Point Cloud (sRGB-encoded), = our core bake of the scene
    in_blender = arrays[f"irradiance_{space}"][..., :3]
    bake_rel = float(np.sqrt(np.mean((in_blender - irr) ** 2) / np.mean(irr ** 2)))
    # per pixel of the sphere camera: the sphere's normal, and the pixels wholly on the sphere
    n, mask = bs.sphere_pixels(SPHERE_CAMERA, SPHERE["centre"], SPHERE["radius"], SPHERE_SIZE)
    want = ALBEDO * sample_cube_bilinear(irr, n)
    native = arrays[f"sphere_{space}"][..., :3].astype(np.float64)
    world = arrays[f"world_{space}"][..., :3].astype(np.float64)
    err_native = bs.block_ratios(native, want, mask, BLOCKS)
    err_world = bs.block_ratios(world, native, mask, BLOCKS)
    pixel_rel = float(np.sqrt(np.mean((native[mask] - want[mask]) ** 2)) / np.sqrt(np.mean(want[mask] ** 2)))
    print(f"\n[cycles reference] {space}: {rec['count']} native splats, sphere {mask.sum()} px in {BLOCKS}x{BLOCKS} "
          f"blocks; Cycles {SAMPLES} spp, denoiser off: {rec['sphere_s']:.1f} s; "
          f"native vs our bake: worst block {np.abs(err_native).max():.2%} (mean {err_native.mean():+.2%}, "
          f"tolerance {SPHERE_RTOL:.0%}), per-pixel rel. RMS {pixel_rel:.2%} (noise + shading); "
          f"our World in Cycles ({WORLD_SAMPLES} spp, {rec['world_s']:.1f} s) vs native: worst block "
          f"{np.abs(err_world).max():.2%}; bake in Blender vs core bake: rel. RMS {bake_rel:.2e}")
    assert rec["muted"] == [True, False, False, False], rec["muted"]  # camera sees them; bounces, shadows don't
    assert bake_rel < 0.01, f"{space}: the bake inside Blender differs from our core bake by {bake_rel:.2%}"
    assert len(err_native) >= BLOCKS * BLOCKS - 2
    assert np.abs(err_native).max() < SPHERE_RTOL, f"{space}: Cycles vs our bake per block:\n{err_native}"
    assert np.abs(err_world).max() < SPHERE_RTOL, f"{space}: Cycles with our World vs native per block:\n{err_world}"


@pytest.mark.parametrize("space", ["srgb", "linear"])
def test_our_pinhole_render_matches_cycles_camera(cycles_run, space):
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    from gs_ibl_addon.core.render.views import ViewBatch
    result, arrays = cycles_run
    rec = result["cases"][space]
    assert rec.get("ok"), rec.get("error")
    ours, _ = shell(space)
    c = VIEW_CAMERA
    batch = ViewBatch.pinhole(c["position"], c["look_at"], c["fov_deg"], *VIEW_SIZE)
    with SplatRenderer(ours) as r:
        img = r.render(batch).images[0].astype(np.float64)
    cyc = arrays[f"view_{space}"].astype(np.float64)
    # both premultiplied (Cycles' film is transparent), alpha = coverage
    diff = float(np.abs(img[..., :3] - cyc[..., :3]).mean() / cyc[..., :3].mean())
    bias = img[..., :3].mean((0, 1)) / cyc[..., :3].mean((0, 1)) - 1.0
    cov = float(np.abs(img[..., 3] - cyc[..., 3]).mean())
    print(f"\n[cycles reference] {space} camera view {VIEW_SIZE[0]}x{VIEW_SIZE[1]}: Cycles {VIEW_SAMPLES} spp "
          f"{rec['view_s']:.1f} s; mean |ours - Cycles| / mean {diff:.2%} (tolerance {VIEW_RTOL:.0%}), mean per "
          f"channel {np.round(bias * 100, 2)}%, coverage |diff| {cov:.4f} (tolerance {COVERAGE_TOL}), "
          f"alpha ours {img[..., 3].mean():.4f} Cycles {cyc[..., 3].mean():.4f}")
    assert diff < VIEW_RTOL and cov < COVERAGE_TOL


def test_real_capture_our_render_matches_cycles(cycles_run):
    """The guitar capture (sRGB) imported by Blender's PLY importer: Cycles' view of it (a one-pixel box filter:
    each pixel the area average) against our pinhole render of the same file with energy-preserving anti-aliasing
    (each splat's footprint widened to a pixel keeping its integral: the area average again). 3DGS's own dilation,
    our pinhole's default because captures are trained with it, adds coverage wherever splats are smaller than a
    pixel; its numbers are printed too."""
    from gs_ibl_addon.core.formats import read_scene
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    from gs_ibl_addon.core.render.views import ViewBatch
    from gs_ibl_addon.core.vk.constants import SORT_RADIAL
    result, arrays = cycles_run
    rec = result["cases"]["guitar"]
    assert rec.get("ok"), rec.get("error")
    scene = read_scene(OUT / "guitar.ply")
    assert rec["native"] and rec["count"] == scene.count
    np.testing.assert_allclose(np.array(rec["matrix"]), np.identity(4), atol=1e-6)  # Blender's import: no transform
    c = capture_camera(scene)
    batch = ViewBatch.pinhole(c["position"], c["look_at"], c["fov_deg"], *CAPTURE_SIZE, up=c["up"])
    with SplatRenderer(scene) as r:
        dilated = r.render(batch).images[0].astype(np.float64)
        # the area average in distance order, as measured: Cycles blends each ray's hits in the order it meets
        # them, which distance order follows more closely than 3DGS's view depth (blue +8.5% against +11.8% here)
        img = r.render(dataclasses.replace(batch, energy_preserving=True, sort=SORT_RADIAL)).images[0].astype(
            np.float64)
    cyc = arrays["view_guitar"].astype(np.float64)
    lit = np.maximum(img[..., 3], cyc[..., 3]) > 0.05
    diff = float(np.abs(img[..., :3] - cyc[..., :3])[lit].mean() / cyc[..., :3][lit].mean())
    bias = img[..., :3][lit].mean(0) / cyc[..., :3][lit].mean(0) - 1.0
    cov = float(np.abs(img[..., 3] - cyc[..., 3]).mean())
    print(f"\n[cycles reference] guitar capture ({scene.count:,} splats, SH degree {scene.sh_degree}) front view "
          f"{CAPTURE_SIZE[0]}x{CAPTURE_SIZE[1]}: Cycles {CAPTURE_SAMPLES} spp {rec['view_s']:.1f} s; over "
          f"{lit.sum()} covered px mean |ours - Cycles| / mean {diff:.2%} (tolerance {CAPTURE_RTOL:.0%}), mean per "
          f"channel {np.round(bias * 100, 2)}% (tolerance {CAPTURE_MEAN_RTOL:.0%}), coverage |diff| {cov:.4f} (tolerance {CAPTURE_COVERAGE_TOL}), alpha "
          f"ours {img[..., 3].mean():.4f} Cycles {cyc[..., 3].mean():.4f}; with 3DGS's dilation instead: alpha "
          f"{dilated[..., 3].mean():.4f}, mean per channel "
          f"{np.round((dilated[..., :3][lit].mean(0) / cyc[..., :3][lit].mean(0) - 1) * 100, 1)}%")
    np.save(OUT / "guitar_ours.npy", img)
    assert diff < CAPTURE_RTOL and np.abs(bias).max() < CAPTURE_MEAN_RTOL and cov < CAPTURE_COVERAGE_TOL
