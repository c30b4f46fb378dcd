"""One probe is not enough (issue 17 part 3), checked against the outside reference: Cycles path-tracing Blender's
native splats, in the bpy 5.3 root with the built zip installed by Blender's installer
(tests/real_blender/local_light_reference.py does the Blender side).

The sample room (samples/room.ply: a window in the +X wall with bright daylight behind it, a ceiling lamp) and two
white diffuse spheres (radius 0.3): one 0.5 m from the window, one in the far corner. The World probe sits in the
middle of the room. Each sphere is rendered by Cycles lit only by the native splats (the reference), then by our
World alone, our World plus a per-object probe, our World plus a 5 x 4 x 3 probe grid over the room, and our
World plus a 3 x 3 x 3 grid over each sphere's own bounds. Compared per 2 x 2 screen blocks of the sphere
and over the whole sphere (mean, per channel); the picture build/matrix/local-light/local_light_spheres.png shows
them all (written there, not over the tracked docs/img/local_light_spheres.png: copy it there when it should change).

Skipped unless the trixie root is made (`scripts/blender_roots.sh ensure trixie`; scripts/test_real_blender.sh).
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import blender_scene as bs  # noqa: E402 (the scenes and Blender set-up shared with the benchmarks)
import test_matrix as matrix  # noqa: E402 (the matrix's runner, installer and roots)

REPO = matrix.REPO
OUT = matrix.OUT / "local-light"
ENTRY = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
PICTURE = OUT / "local_light_spheres.png"

SIZE = 40
FOV = 40.0
ALBEDO = 0.8
SPHERES = {
    "window": {"centre": [2.2, 0.0, 1.4], "radius": 0.3, "camera_offset": [0.0, -1.2, 0.1]},
    "corner": {"centre": [-2.2, 1.8, 0.8], "radius": 0.3, "camera_offset": [1.0, -0.6, 0.2]},
}
PROBE = [0.0, 0.0, 1.2]
GRID = {"centre": [0.0, 0.0, 1.4], "half": [2.7, 2.2, 1.1], "shape": [5, 4, 3]}
FINE_GRID = {"shape": [3, 3, 3]}  # over each sphere's own bounds
NATIVE_SAMPLES = int(os.environ.get("GS_IBL_CYCLES_SAMPLES", 1024))
SAMPLES = 128
METHODS = ("one", "object", "grid", "fine")
PANO_HEIGHT = 96  # Cycles' equirectangular view of the splats from each sphere's centre


def _spheres_args():
    out = {}
    for name, s in SPHERES.items():
        c = np.asarray(s["centre"])
        out[name] = {"centre": s["centre"], "radius": s["radius"],
                     "camera": {"position": (c + s["camera_offset"]).tolist(), "look_at": s["centre"],
                                "fov_deg": FOV}}
    return out


def sphere_mask(name: str) -> np.ndarray:
    """Pixels (top row first) well inside the sphere's outline."""
    s = _spheres_args()[name]
    return bs.sphere_pixels(s["camera"], s["centre"], s["radius"], SIZE)[1]


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    matrix.require_root(ENTRY.root)
    from gs_ibl_addon.core.formats import read_scene
    OUT.mkdir(parents=True, exist_ok=True)
    runner = matrix.Runner(ENTRY, tmp_path_factory.mktemp("local"))
    try:
        bs.write_room_for_blender(runner.host / "room.ply", REPO / "samples" / "room.ply")
        args = {"work": str(runner.inner), "ply": str(runner.inner / "room.ply"), "size": SIZE, "albedo": ALBEDO,
                "spheres": _spheres_args(), "probe": PROBE, "grid": GRID, "fine_grid": FINE_GRID, "face_size": 64,
                "native_samples": NATIVE_SAMPLES, "samples": SAMPLES, "threads": 2,
                "pano_height": PANO_HEIGHT, "pano_samples": 16}
        result = matrix.run_script(runner, HERE / "local_light_reference.py", args, "GSIBL-LOCAL-RESULT", "local")
        arrays = {p.stem: np.load(p) for p in runner.host.glob("*.npy")}
        yield result, arrays, read_scene(REPO / "samples" / "room.ply")
    finally:
        keep = OUT / "run"
        shutil.rmtree(keep, ignore_errors=True)
        shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.zip", "*.blend*"))
        runner.close()


def mean_radiance_ratio(pano: np.ndarray, room, centre) -> np.ndarray:
    """Per channel: the solid-angle mean of Cycles' equirectangular view (H, 2H) over our probe's at ``centre``
    (orientation-free: the mean of the irradiance over all normals is pi times this mean)."""
    from gs_ibl_addon.core import cubemap
    from gs_ibl_addon.core.bake import ProbeSettings, bake_probe
    h = pano.shape[0]
    w_row = np.cos((np.arange(h) + 0.5) / h * np.pi - np.pi / 2)  # cos(latitude) of each row
    cyc = (pano[..., :3].astype(np.float64) * w_row[:, None, None]).sum((0, 1)) / (w_row.sum() * pano.shape[1])
    p = bake_probe(room, centre, ProbeSettings(method="exact", face_size=128, irradiance_size=8))
    rad = np.asarray(p.radiance)[..., :3].astype(np.float64)
    sa = cubemap.texel_solid_angles(rad.shape[1])[None, :, :, None]
    ours = (rad * sa).sum((0, 1, 2)) / (4 * np.pi)
    return cyc / ours


def _picture(arrays) -> None:
    """Rows: the spheres; columns: native Cycles, one probe, per-object probe, room grid, grid over the sphere (one
    exposure for all)."""
    from gs_ibl_addon.core.image_io import write_png_preview
    rows = []
    for name in SPHERES:
        blank = np.ones((SIZE, SIZE, 3), np.float32)
        tiles = [arrays.get(f"{m}_{name}", blank)[..., :3] for m in ("native", *METHODS)]
        gap = np.ones((SIZE, 2, 3), np.float32)
        rows.append(np.concatenate(sum(([t, gap] for t in tiles), [])[:-1], 1))
    img = np.concatenate([rows[0], np.ones((2, rows[0].shape[1], 3), np.float32), rows[1]], 0)
    img = np.repeat(np.repeat(img, 4, 0), 4, 1)  # 40 px renders, shown at 160 px
    write_png_preview(PICTURE, img)


def test_local_light_matches_native_cycles(local_run):
    result, arrays, room = local_run
    assert result.get("ok"), result.get("error")
    assert result["native"]
    # Blender's PLY importer put the splats where our reader does (no axis change), so the spheres stand where meant
    head = np.asarray(result["positions_head"])
    assert np.abs(head - room.positions[:len(head)]).max() < 1e-4
    lines = [f"\n[local light] Cycles {SIZE}x{SIZE}: native {NATIVE_SAMPLES} spp, ours {SAMPLES} spp; "
             f"World bake {result['bake_s']:.1f} s; variation check {result['variation_s']:.1f} s "
             f"({result['variations']}); per-object bake {result['object_bake_s']:.1f} s; grid "
             f"{'x'.join(map(str, GRID['shape']))} bake {result['grid_bake_s']:.1f} s"]
    means, worst = {}, {}
    for name in SPHERES:
        mask = sphere_mask(name)
        native = arrays[f"native_{name}"][..., :3].astype(np.float64)
        for m in (*METHODS, "reloaded"):
            if f"{m}_{name}" not in arrays:
                continue
            got = arrays[f"{m}_{name}"][..., :3].astype(np.float64)
            means[(name, m)] = got[mask].mean(0) / native[mask].mean(0)
            worst[(name, m)] = np.abs(bs.block_ratios(got, native, mask, 2)).max()
            lines.append(f"  {name:6s} {m:8s}: whole sphere / native {np.round(means[(name, m)], 3)}, worst 2x2 "
                         f"block {worst[(name, m)]:.1%}")
    print("\n".join(lines + [f"  variation: {result['variation']}", f"  {result['grid_report']}",
                             f"  {result['fine_report']} in {result['fine_bake_s']:.1f} s"]))
    _picture(arrays)

    for name, s in SPHERES.items():  # the splats' mean radiance all around the centre: Cycles' camera vs our probe
        lines = [f"  {name}: mean radiance seen from the centre, Cycles panorama / our probe "
                 f"{np.round(mean_radiance_ratio(arrays[f'pano_{name}'], room, s['centre']), 3)}"]
        print("\n".join(lines))

    def off(name, m):
        return float(np.abs(means[(name, m)] - 1).max())
    np.testing.assert_allclose(means[("window", "reloaded")], means[("window", "grid")], rtol=0.03)
    # one probe in the middle of the room misleads both spheres, and the check says so
    assert off("window", "one") > 0.4 and off("corner", "one") > 0.4
    assert all(("use a per-object probe" in line) for line in result["variation"] if line.startswith(tuple(SPHERES)))
    # local light brings both to within 20% (measured 4-16%: the light still varies across each sphere, and in the
    # corner our splats' light is 7-10% above Cycles' even at the surface: docs/stability.md) ...
    for name in SPHERES:
        for m in ("object", "grid", "fine"):
            assert off(name, m) < 0.2 and off(name, m) < off(name, "one") / 3, (name, m, means[(name, m)])
    # ... and a 3 x 3 x 3 grid over the window sphere's own bounds to within 3% (measured 0.6-2.8%, worst block 6.8%)
    assert off("window", "fine") < 0.04 and worst[("window", "fine")] < worst[("window", "object")] / 2
