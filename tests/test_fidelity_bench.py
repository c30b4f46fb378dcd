"""A dry run of the GPU machine's final-frame benchmarks (benchmarks/gpu_run.sh final) on this machine's device:
the Python commands of that mode, read from gpu_run.sh itself, run with tiny sizes and a stand-in for gsplat
(torch and CUDA are only on the GPU machine): fidelity_bench's numpy port of gsplat's classic path plays gsplat, as
tests/test_peer_bench.py's FakeGsplat does for peer_bench. A mistake in these scripts or in gpu_run.sh's options
would otherwise show first in the one call of that machine. Also: the camera given to gsplat is ours (same rays),
and the numpy port draws one splat as 3DGS's formula says."""
import csv
import math
import os
import re
import shlex
import sys
import types

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, "benchmarks")


def final_commands(out: str) -> list[list[str]]:
    """The argv of each python3 command of gpu_run.sh's final mode, ``$out`` replaced by ``out``."""
    text = open(os.path.join(BENCH, "gpu_run.sh")).read()
    start = text.index('elif [ "$1" = final ]')
    block = text[start:text.index('elif [ "$1" = ', start + 1)]  # to the next mode's branch
    block = block.replace("\\\n", " ")
    cmds = []
    for line in block.splitlines():
        m = re.search(r"python3 (benchmarks/\S+\.py)(.*?)(\|\||$)", line)
        if m:
            cmds.append([m.group(1)] + shlex.split(m.group(2).replace("$out", out)))
    return cmds


class StandIn:
    """gsplat's place in fidelity_bench (GsplatCuda): the numpy port's image (not a ClassicNumpy, so that the
    --check-port rows are made as on the GPU machine)."""
    name = "gsplat (stand-in: numpy port)"

    def __init__(self, scene, near, far) -> None:
        import fidelity_bench
        self.port = fidelity_bench.ClassicNumpy(scene, near, far)

    def render(self, cv):
        return self.port.render(cv)


class FrameStandIn:
    """gsplat's place in frame_cost_bench (gsplat_peer)."""
    name = "gsplat"

    def rep(self) -> dict:
        return {"gpu_ms": 1.0, "mesh_depth": 0.0, "splats": 1.1, "post": 0.0, "wall_ms": 1.1, "pairs": 7}

    def kernel_ms(self):
        return [("fully_fused_projection_packed_fwd_kernel", 0.1), ("rasterize_to_pixels_fwd_kernel", 0.3),
                ("at::native::elementwise_kernel", 0.01)]


@pytest.fixture
def benches(monkeypatch):
    monkeypatch.syspath_prepend(BENCH)
    torch = types.ModuleType("torch")
    torch.zeros = lambda *a, **k: None
    torch.cuda = types.SimpleNamespace(empty_cache=lambda: None, is_available=lambda: False)
    monkeypatch.setitem(sys.modules, "torch", torch)
    import fidelity_bench
    import frame_cost_bench
    import peer_bench
    monkeypatch.setattr(peer_bench, "load_gsplat", lambda: types.SimpleNamespace(__version__="stand-in"))
    monkeypatch.setattr(fidelity_bench, "GsplatCuda", StandIn)
    monkeypatch.setattr(frame_cost_bench, "gsplat_peer", lambda scene, cv: FrameStandIn())
    return fidelity_bench, frame_cost_bench


def test_final_mode_dry(benches, tmp_path):
    fidelity_bench, frame_cost_bench = benches
    cmds = final_commands(str(tmp_path))
    assert [c[0] for c in cmds] == ["benchmarks/fidelity_bench.py", "benchmarks/frame_cost_bench.py",
                                    "benchmarks/frame_cost_bench.py"]
    fid, cost, plot = (c[1:] for c in cmds)
    # gpu_run.sh's own options, sizes made small for lavapipe (argparse keeps the last of a repeated option)
    summaries = fidelity_bench.main(fid + ["--size", "64x36", "--check-port", "32x18"])
    rows = list(csv.DictReader(open(tmp_path / "fidelity.csv")))
    ours = [r for r in rows if r["peer"] == StandIn.name]
    port = [r for r in rows if r["peer"] == "numpy-port"]
    assert len(ours) == 16 and len(port) == 16  # two captures x eight views, and the port's check of each
    assert {r["capture"] for r in ours} == {"guitar", "room"}
    assert all(float(r["psnr"]) == 99.0 for r in port)  # the stand-in is the port: identical
    assert all(10 < float(r["psnr"]) <= 99 for r in ours)
    for r in ours:
        if r["view"] == "v0":  # a render border's window and the frame without the cut draw the same pixels (a
            # window this small, 32x18, has its tiles' lists split into chunks, each blended to its end: within T_MIN)
            assert float(r["window_max_diff"]) <= 1e-4 and float(r["nocut_max_diff"]) == 0.0, r
    shifted = [r for r in ours if float(r["shift_x"]) != 0.0]
    assert len(shifted) == 4
    worst = list(csv.DictReader(open(tmp_path / "fidelity_worst.csv")))
    assert len(worst) == 2 * 7 and {r["class"] for r in worst} >= {"order", "near", "edge", "needle", "other"}
    assert len(list(csv.DictReader(open(tmp_path / "fidelity_splats.csv")))) > 0
    for s in summaries:
        assert s["worst_psnr"] <= s["median_psnr"] and "classes" in s and "psnr_if_distance_order" in s
        assert (tmp_path / f"fidelity_{s['capture']}_worst.png").stat().st_size > 1000

    frame_cost_bench.main(cost + ["--scenes", "room,guitar,random:3k,shell:3k", "--size", "96x54", "--rounds", "1",
                                  "--block", "1", "--warmup", "0"])
    rows = list(csv.DictReader(open(tmp_path / "frame_cost.csv")))
    assert [r["renderer"] for r in rows] == ["gs-ibl", "gs-ibl cut", "gsplat"] * 4
    assert [r["scene"] for r in rows[::3]] == ["room", "guitar", "random 0.003M", "shell 0.003M"]
    for r in rows:
        if r["renderer"].startswith("gs-ibl"):
            assert float(r["raster_ms"]) > 0 and float(r["splats_ms"]) > 0 and int(r["pairs"]) > 0
    cut = [r for r in rows if r["renderer"] == "gs-ibl cut"]
    assert all(float(r["mesh_depth_ms"]) > 0 and 0 < float(r["mesh_share"]) < 1 for r in cut)
    g = rows[2]
    assert float(g["raster_ms"]) == 0.3 and float(g["other_ms"]) == 0.01
    frame_cost_bench.main(plot)
    assert (tmp_path / "final-frame-cost.png").stat().st_size > 1000


def test_gsplat_camera_is_ours(benches):
    """The view matrix and K given to gsplat send each of our pixel rays to that pixel's centre (lens shift and a
    non-square frame included)."""
    fb = benches[0]
    m = fb.look_at(np.array([1.0, -2.0, 0.5]), np.array([0.2, 0.3, 0.1]), np.array([0.0, 0.0, 1.0]))
    tx = math.tan(math.radians(30))
    cv = fb.CameraView("t", m, tx, tx * 30 / 50, 50, 30, (0.12, -0.07))
    vm, k = fb.opencv_camera(cv)
    dirs = fb.our_batch(cv).views[0].pixel_directions()
    cam = dirs @ vm[:3, :3].T  # directions in the camera's frame
    px = cam @ k.T
    px = px[..., :2] / px[..., 2:]
    jj, ii = np.meshgrid(np.arange(50) + 0.5, np.arange(30) + 0.5)
    assert np.abs(px[..., 0] - jj).max() < 1e-9 and np.abs(px[..., 1] - ii).max() < 1e-9
    assert np.allclose(vm[:3, :3] @ vm[:3, :3].T, np.eye(3)) and np.linalg.det(vm[:3, :3]) > 0


def test_numpy_port_draws_one_splat_as_3dgs(benches):
    """One round splat straight ahead: alpha = opacity exp(-d^2 / (2 (sigma^2 + 0.3))) in pixels, cut at 1/255."""
    fb = benches[0]
    from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc
    sh = rgb_to_sh_dc(np.array([[0.2, 0.5, 0.8]], np.float32))[:, None, :]
    scene = SplatScene(np.array([[0.0, 0.0, 0.0]], np.float32), np.full((1, 3), 0.05, np.float32),
                       np.array([[1.0, 0.0, 0.0, 0.0]], np.float32), np.array([0.7], np.float32), sh,
                       colour_space="linear")
    m = fb.look_at(np.array([0.0, -2.0, 0.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    cv = fb.CameraView("t", m, 0.5, 0.5, 64, 64, (0.0, 0.0))
    img = fb.ClassicNumpy(scene, 0.01, 100.0).render(cv)
    f = 64 / (2 * 0.5)
    var = (0.05 * f / 2.0) ** 2 + 0.3
    jj, ii = np.meshgrid(np.arange(64) + 0.5, np.arange(64) + 0.5)
    alpha = 0.7 * np.exp(-((jj - 32) ** 2 + (ii - 32) ** 2) / (2 * var))
    alpha[alpha < 1 / 255] = 0
    assert np.abs(img[..., 3] - alpha).max() < 1e-5
    assert np.allclose(img[..., :3], alpha[..., None] * [0.2, 0.5, 0.8], atol=1e-5)
