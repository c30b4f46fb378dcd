"""A dry run of the GPU machine's benchmark (benchmarks/gpu_run.sh full) on this machine's device: peer_bench's
cube grid and camera frames with the kernels' A/B rows, the kernel table written from them, and the chart, with
tiny scenes and a stand-in for gsplat (torch and CUDA are only on the GPU machine). A mistake in these scripts
would otherwise show first in the one call of that machine."""
import csv
import json
import os
import sys
import types

import numpy as np
import pytest

from gs_ibl_addon.core.render import kernel_table as KT

BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks")


class FakeGsplat:
    """What run_bench asks of peer_bench.Gsplat, without torch: empty images of the view's shape."""
    name = "gsplat"

    def __init__(self, scene) -> None:
        pass

    def set_view(self, view) -> None:
        import peer_bench
        batch = peer_bench.view_batch(view)
        self.shape = (len(batch.views), batch.views[0].height, batch.views[0].width, 4)

    def rep(self) -> dict:
        return {"gpu_ms": 1.0, "wall_ms": 1.1, "pairs": 7}

    def images(self) -> np.ndarray:
        return np.zeros(self.shape, np.float32)

    def kernel_ms(self):
        return [("fully_fused_projection_packed_fwd_kernel", 0.1), ("rasterize_to_pixels_fwd_kernel", 0.3),
                ("void cub::DeviceRadixSortOnesweepKernel<...>", 0.05), ("isect_tiles", 0.02),
                ("at::native::elementwise_kernel", 0.01)]


@pytest.fixture
def peer(monkeypatch):
    monkeypatch.syspath_prepend(BENCH)
    torch = types.ModuleType("torch")
    torch.zeros = lambda *a, **k: None
    torch.cuda = types.SimpleNamespace(empty_cache=lambda: None)
    monkeypatch.setitem(sys.modules, "torch", torch)
    import peer_bench
    from gs_ibl_addon.core.render import renderer
    for k, v in peer_bench.default_switches().items():  # the rows set the module switches: put them back after
        monkeypatch.setattr(renderer, k, v)
    monkeypatch.setattr(peer_bench, "load_gsplat", lambda: types.SimpleNamespace(__version__="fake"))
    monkeypatch.setattr(peer_bench, "Gsplat", FakeGsplat)
    return peer_bench


def test_gsplat_kernels_by_stage(peer):
    st = peer.gsplat_stages(FakeGsplat(None).kernel_ms())
    assert st["preprocess"] == 0.1 and st["raster"] == 0.3 and st["sort_tiles"] == 0.05 and st["emit"] == 0.02
    assert st["other"] == 0.01
    assert peer.parse_views("32", "1920x1080") == [("cube", 32, 32), ("camera", 1920, 1080)]


def test_full_run_dry(peer, tmp_path, monkeypatch):
    grid, cams = tmp_path / "peer.csv", tmp_path / "camera.csv"
    monkeypatch.setattr(sys, "argv", [
        "peer_bench.py", "bench", "--scenes", "shell,random", "--counts", "3000", "--faces", "16,32",
        "--cameras", "96x54", "--ab", "plain,strips,emit-slot,emit-splat", "--gsplat-stages", "cameras",
        "--warmup", "0", "--rounds", "1", "--block", "1", "--deadline", "600", "--csv", str(grid),
        "--camera-csv", str(cams)])
    peer.main()
    rows = list(csv.DictReader(open(grid)))
    cam = list(csv.DictReader(open(cams)))
    assert len(rows) == 2 * 2 * 6 and len(cam) == 2 * 6  # scenes x views x (ours, 4 variants, gsplat)
    ours = [r for r in rows + cam if r["renderer"] == "gs-ibl"]
    assert all(r["raster_kernel"] and r["emit_kernel"] and r["device_class"] for r in ours)
    for r in rows + cam:
        if r["variant"]:  # every A/B row draws the default's image (bit for bit: the diff is exactly 0)
            assert float(r["image_diff"]) == 0.0, r
    assert {(r["view"], r["width"], r["height"], r["face"]) for r in cam} == {("camera", "96", "54", "96")}
    g = next(r for r in cam if r["renderer"] == "gsplat")
    assert float(g["raster_ms"]) == 0.3 and float(g["other_ms"]) == 0.01
    by_variant = {r["variant"]: r for r in cam if r["scene"] == "shell"}
    assert by_variant["strips"]["raster_kernel"] == "gs_raster_conic_strips"  # 96 wide: the conic kernels
    assert by_variant["plain"]["raster_kernel"] == "gs_raster_conic"
    assert by_variant["emit-splat"]["emit_kernel"] == "gs_emit_per_splat"
    assert by_variant["emit-slot"]["emit_kernel"] == "gs_emit"

    # the kernel table from those rows, the committed table's other classes kept
    sys.path.insert(0, BENCH)
    import raster_ab_bench
    out = tmp_path / "kernel_table.json"
    monkeypatch.setattr(sys, "argv", ["raster_ab_bench.py", "table", str(grid), str(cams), str(tmp_path / "none.csv"),
                                      "--merge", KT.TABLE_PATH, "--out", str(out)])
    raster_ab_bench.main()
    table = KT.KernelTable(json.load(open(out)), str(out))
    committed = KT.load()
    cls = rows[0]["device_class"]
    measured = {(r.device, r.stage) for r in table.rows}
    assert (cls, "raster") in measured and (cls, "emit") in measured
    for dev in committed.devices():
        if dev != cls:  # kept as they were
            assert [r for r in table.rows if r.device == dev] == [r for r in committed.rows if r.device == dev]
    assert {r.face_min for r in table.rows if (r.device, r.stage) == (cls, "raster")} >= {1}

    monkeypatch.setattr(sys, "argv", ["peer_bench.py", "plot", "--csv", str(grid), "--png", str(tmp_path / "p.png")])
    peer.main()
    assert (tmp_path / "p.png").stat().st_size > 1000
