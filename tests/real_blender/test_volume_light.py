"""The light volume in a real Blender (bpy 5.3, the built zip installed by Blender's installer; issue 37):
tests/real_blender/volume_scene.py does the Blender side.

1. The volume group renders core/probe/volume.py sample_packed: a unit sphere whose material is the group's
   Irradiance into an Emission, the core's synthetic volume (a wall the visibility sees), EEVEE and Cycles: sphere
   pixels within 1% median, 3% at the 95th percentile (the pixels on the wall's shadow edge are the worst).
2. Motion without a re-bake: a white sphere (albedo 0.8) keyframed from the window to under the lamp in the sample
   room, one Lighting Volume bake; in EEVEE at each frame the sphere's mean is 0.8 x sample_packed's mean at its
   surface points there (from the file's own atlases) within 3% per channel, and the light differs along the path.

Skipped unless the trixie root is made (`scripts/blender_roots.sh ensure trixie`; scripts/test_real_blender.sh).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import blender_scene as bs  # noqa: E402
import test_matrix as matrix  # noqa: E402

REPO = matrix.REPO
ENTRY = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
SIZE = 32
RADIUS = 0.25
FOLLOW = 0.6  # the following camera's ortho scale
PATH = [[2.2, 0.0, 1.3], [1.4, 0.0, 1.6], [0.6, 0.0, 1.9], [0.0, 0.0, 2.2]]  # window -> under the lamp


def _synthetic():
    from gs_ibl_addon.core.probe import volume as pv
    from gs_ibl_addon.core.probe.grid import GridSpec
    spec = GridSpec((-1.3, -1.2, -1.1), (1.3, 1.2, 1.1), (4, 3, 3))

    def irradiance(p, n):
        return np.stack([0.5 + 0.15 * p[..., 0] + 0.1 * n[..., 1], 0.4 + 0.3 * n[..., 2] + 0.1 * p[..., 2],
                         0.3 + 0.2 * n[..., 0] - 0.05 * p[..., 1]], -1)
    refine = np.ones(pv.cell_shape(spec), int)
    refine[1, 0, 0], refine[2, 1, 1] = 4, 2  # bricks where the sphere is: the group's brick path in every Blender
    v = pv.synthetic_volume(spec, irradiance, wall_x=0.5, refine=refine)
    return spec, (*pv.pack_atlas(v), pv.pack_cells(v)), v.tiles


def _sphere_points(size: int, scale: float, radius: float, max_r: float = 0.85):
    """(mask of pixels, unit normals there) of a sphere of ``radius`` filling an ortho view of ``scale`` from +X."""
    c = (np.arange(size) + 0.5) / size * scale - scale / 2
    zz, yy = np.meshgrid(c[::-1], c, indexing="ij")
    mask = yy * yy + zz * zz < (max_r * radius) ** 2
    n = np.stack([np.sqrt(np.maximum(radius ** 2 - yy ** 2 - zz ** 2, 0.0)), yy, zz], -1)[mask] / radius
    return mask, n


@pytest.fixture(scope="module")
def volume_run(tmp_path_factory):
    matrix.require_root(ENTRY.root)
    runner = matrix.Runner(ENTRY, tmp_path_factory.mktemp("volume"))
    spec, (irr, vis, cells), tiles = _synthetic()
    try:
        bs.write_room_for_blender(runner.host / "room.ply", REPO / "samples" / "room.ply")
        np.save(runner.host / "irr.npy", irr)
        np.save(runner.host / "vis.npy", vis)
        np.save(runner.host / "cells.npy", cells)
        from gs_ibl_addon.core.formats.ply import write_ply
        from gs_ibl_addon.core.probe import volume_rooms as vr
        rooms = vr.two_rooms()
        write_ply(runner.host / "rooms.ply", rooms.scene)
        args = {"work": str(runner.inner), "ply": str(runner.inner / "room.ply"), "size": SIZE, "threads": 2,
                "samples": 16, "eevee_samples": 16, "albedo": 0.8, "radius": RADIUS, "path": PATH,
                "probe": [0.0, 0.0, 1.2], "follow_scale": FOLLOW,
                "spec": {"lo": list(spec.lo), "hi": list(spec.hi), "shape": list(spec.shape)}, "tiles": tiles,
                "rooms": {"ply": str(runner.inner / "rooms.ply"), "sphere": list(vr.SPHERE_CENTRE),
                          "radius": vr.SPHERE_RADIUS, "cube": [-0.8, 0.0, 1.2], "probe": [1.0, 0.5, 1.2],
                          "probes": 64}}
        result = matrix.run_script(runner, HERE / "volume_scene.py", args, "GSIBL-VOLUME-RESULT", "volume")
        arrays = {p.stem: np.load(p) for p in runner.host.glob("*.npy")}
        yield result, arrays, (spec, irr, vis, cells), rooms
    finally:
        runner.close()


def test_group_matches_sample_packed(volume_run):
    from gs_ibl_addon.core.probe import volume as pv
    result, arrays, (spec, irr, vis, cells), _rooms = volume_run
    assert result.get("ok"), result.get("error")
    mask, n = _sphere_points(SIZE, 2.4, 1.0)
    want = pv.sample_packed(irr, vis, spec, n, n, cells=cells)
    for engine in ("EEVEE", "CYCLES"):
        got = arrays[f"group_{engine}"][..., :3][mask]
        rel = np.abs(got - want).max(-1) / np.abs(want).mean()
        print(f"\n{result['blender']} {engine}: volume group vs sample_packed: median {100 * np.median(rel):.3f}%, "
              f"95th pct {100 * np.percentile(rel, 95):.3f}%, max {100 * rel.max():.2f}%")
        assert np.median(rel) < 0.01 and np.percentile(rel, 95) < 0.03


def test_a_moving_sphere_is_lit_where_it_stands(volume_run):
    from gs_ibl_addon.core.probe import volume as pv
    from gs_ibl_addon.core.probe.grid import GridSpec
    result, arrays, _, _rooms = volume_run
    assert result.get("ok"), result.get("error")
    print("\n" + "\n".join(result["local_report"]))
    assert result["ball_light"] == "volume"
    s = result["volume_spec"]
    spec = GridSpec(tuple(s["lo"]), tuple(s["hi"]), tuple(s["shape"]))
    irr, vis = arrays["atlas_irr"].astype(np.float64), arrays["atlas_vis"].astype(np.float64)
    cells = arrays["atlas_cells"].astype(np.float64)
    mask, n = _sphere_points(SIZE, FOLLOW, RADIUS)
    wants = []
    for f, loc in enumerate(PATH, 1):
        px = arrays[f"frame_{f}"]
        keep = mask & (px[..., 3] > 0.999)
        nn = n[keep[mask]]
        got = px[..., :3][keep].mean(0)
        want = 0.8 * pv.sample_packed(irr, vis, spec, np.asarray(loc) + RADIUS * nn, nn, cells=cells).mean(0)
        wants.append(want)
        print(f"frame {f} at {loc}: EEVEE mean {np.round(got, 4)}, 0.8 x sample_packed {np.round(want, 4)}, "
              f"ratio {np.round(got / want, 4)}")
        assert np.all(np.abs(got / want - 1) < 0.03)
    means = [w.mean() for w in wants]
    assert max(means) > 1.1 * min(means)
    print(json.dumps(result["times"]))


def test_no_light_leaks_through_a_splat_wall(volume_run):
    """Issue 37's leak target in Blender 5.3 through the extension's own import and Bake: the two rooms, a sphere in
    the dark room, Lighting Volume at 64 probes (a coarse grid with a cell across the wall): the file's volume at
    the sphere within 3% of the exact irradiance, its grid alone too; that grid without visibility leaks (the bpy
    module's test: 0.5-0.8%, 0.4%, +25..+52%)."""
    from gs_ibl_addon.core.probe import volume as pv
    from gs_ibl_addon.core.probe import volume_rooms as vr
    from gs_ibl_addon.core.probe.grid import GridSpec
    result, arrays, _, rooms = volume_run
    assert result.get("ok"), result.get("error")
    print("\n" + "\n".join(result["rooms_report"]))
    # a native import stores the file's linear colours re-encoded for Blender's sRGB rule (splats/object.py
    # _fill_pointcloud), a mesh import as they are: either way the radiance is the file's
    assert result["rooms_colour_space"] in ("SRGB", "LINEAR")
    s = result["rooms_spec"]
    spec = GridSpec(tuple(s["lo"]), tuple(s["hi"]), tuple(s["shape"]))
    irr, vis, cells = (arrays[f"rooms_{k}"].astype(np.float64) for k in ("irr", "vis", "cells"))
    pts, nrm = vr.sphere_points(200)
    exact = rooms.exact(pts, nrm, 4000)
    got = pv.sample_packed(irr, vis, spec, pts, nrm, cells=cells).mean(0) / exact.mean(0)
    grid = pv.sample_packed(irr, vis, spec, pts, nrm).mean(0) / exact.mean(0)
    blind = pv.sample_packed(irr, vis, spec, pts, nrm, visibility=False)
    print(f"{result['blender']}: dark room's sphere, ours / exact {np.round(got, 4)}, the grid alone "
          f"{np.round(grid, 4)}, without visibility worst point {np.max(blind / exact):.2f}x; bake "
          f"{result['times']['rooms_bake']:.1f} s")
    assert np.all(np.abs(got - 1) < 0.03) and np.all(np.abs(grid - 1) < 0.03)
    assert np.max(blind / exact) > 1.5

