"""The kernel table (render/kernel_table.json, render/kernel_table.py): which raster and emit kernels a device takes,
from A/B measurements. Checked here: the committed table parses and names only kernels that exist; it is what the
writer (benchmarks/raster_ab_bench.py table) makes of the committed measurements, and its rule takes what those
measurements say; the renderer takes the table's kernels (the module switches override them; a device class with
no rows, or an unreadable table, takes the fallback); and whichever kernels are picked, the images and depths are
the same bit for bit."""
import json
import os
import sys
import warnings

import numpy as np
import pytest

from gs_ibl_addon.core.render import kernel_table as KT
from gs_ibl_addon.core.render import renderer as R
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.vk import get_context
from gs_ibl_addon.core.vk.kernels import KERNELS
from test_raster_plane import _mixed, _wall
from test_raster_strips import _small_shell

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, "benchmarks")


def _sources() -> list[str]:
    """The measurements the committed table names as its sources ("path: device date"), in its order."""
    with open(KT.TABLE_PATH) as f:
        named = json.load(f)["sources"]
    paths = list(dict.fromkeys(entry.split(": ")[0] for entries in named.values() for entry in entries))
    missing = [p for p in paths if not os.path.exists(os.path.join(ROOT, p))]
    if missing:
        pytest.fail(f"the kernel table's sources {missing} are not in the repository: commit the CSVs it was "
                    "written from under docs/bench/ and write it again from them (benchmarks/raster_ab_bench.py "
                    "table CSV ...)")
    return [os.path.join(ROOT, p) for p in paths]


def _bench(name: str):
    sys.path.insert(0, BENCH)
    try:
        return __import__(name)
    finally:
        sys.path.remove(BENCH)


def test_every_choice_names_kernels_that_exist():
    spv = os.path.join(ROOT, "gs_ibl_addon", "shaders")
    for stage, choices in KT.CHOICES.items():
        assert KT.FALLBACK[stage] in choices
        for names in choices.values():
            for name in names:
                assert name in KERNELS and os.path.exists(os.path.join(spv, name + ".spv")), name
    # the raster kernel names the renderer builds are the ones declared for each choice
    for face in (32, 64, 1024):
        batch = ViewBatch.cubemap(np.zeros(3), face)
        assert R.raster_kernel(batch, False) in KT.CHOICES["raster"]["plain"]
        assert R.raster_kernel(batch, True) in KT.CHOICES["raster"]["strips"]


def test_committed_table_parses():
    with open(KT.TABLE_PATH) as f:
        data = json.load(f)
    table = KT.KernelTable(data, KT.TABLE_PATH)
    assert {"cpu", "nvidia"} <= set(table.devices())
    for row in table.rows:
        assert row.kernel in KT.CHOICES[row.stage]
    # every (device, stage) it has rows for is covered from 1 up, without a gap
    for dev in table.devices():
        for stage in {r.stage for r in table.rows if r.device == dev}:
            rows = sorted((r for r in table.rows if (r.device, r.stage) == (dev, stage)), key=lambda r: r.face_min)
            assert rows[0].face_min == 1 and rows[-1].face_max is None
            assert all(a.face_max + 1 == b.face_min for a, b in zip(rows, rows[1:]))
    assert KT.load() is KT.load()  # read once


def test_committed_table_is_what_the_writer_makes_of_the_measurements(tmp_path):
    out = tmp_path / "table.json"
    _bench("raster_ab_bench").write_table(_sources(), str(out))
    with open(out) as f, open(KT.TABLE_PATH) as g:
        made, committed = json.load(f), json.load(g)
    assert made["rows"] == committed["rows"]
    assert made["fallback"] == committed["fallback"] and made["tolerance"] == committed["tolerance"]


def test_the_rule_takes_what_the_measurements_say():
    table = KT.load()
    # lavapipe (docs/bench/raster_ab_lavapipe.csv, emit_ab_lavapipe.csv): strips at 32²-512², the per-splat emit
    # at 32²-1024² (strips lost only the random scene at 256², by 1.8% of the frame, and won the shell by 16%)
    for face in (16, 32, 64, 128, 256, 512, 1024, 1920):
        assert table.pick("cpu", "raster", face).kernel == "strips"
        assert table.pick("cpu", "emit", face).kernel == "splat"
    # every measured size of every device class and stage: a kernel at least as fast in every cell is taken (the
    # H200 run of 2026-12-05: docs/bench/peer_nvidia-h200_2026-12-05.csv and camera_nvidia-h200_2026-12-05.csv), and one that loses by
    # more than 10% in some cell is not taken where the other loses by 10% or less everywhere
    cells, _ = _bench("raster_ab_bench").table_cells(_sources())
    groups = {}
    for c in cells:
        groups.setdefault((c.device, c.stage, c.face), {}).setdefault((c.scene, c.splats), {})[c.kernel] = c.ms
    checked = 0
    for (dev, stage, face), by_cell in groups.items():
        full = [t for t in by_cell.values() if len(t) == 2]
        picked = table.pick(dev, stage, face).kernel
        for k in KT.CHOICES[stage]:
            other = next(x for x in KT.CHOICES[stage] if x != k)
            worst = max(t[k] / min(t.values()) - 1 for t in full)
            worst_other = max(t[other] / min(t.values()) - 1 for t in full)
            if worst == 0 and worst_other > KT.TOLERANCE:
                assert picked == k, (dev, stage, face)
            if worst > 0.10 and worst_other <= 0.10:
                assert picked == other, (dev, stage, face)
        checked += 1
    assert checked >= 5 + 4 + 4  # lavapipe: raster at 5 sizes, emit at 4; the H200: raster at 4 at least
    for dev in table.devices():  # a class measured for one stage only takes the fallback for the other
        for stage in KT.CHOICES:
            if not any((r.device, r.stage) == (dev, stage) for r in table.rows):
                assert table.pick(dev, stage, 64) == KT.Pick(KT.FALLBACK[stage],
                                                             f"fallback: no {stage} row for {dev!r} at 64")


def _cells(face_times: dict, device="gpu", stage="raster") -> list:
    """face -> [(plain ms, strips ms) per scene]"""
    out = []
    for face, cells in face_times.items():
        for i, (p, s) in enumerate(cells):
            out += [KT.Cell(device, stage, f"s{i}", 1, face, "plain", p), KT.Cell(device, stage, f"s{i}", 1, face,
                                                                                    "strips", s)]
    return out


def test_rule_minimises_the_worst_loss_and_merges_ranges():
    rows = KT.choose_rows(_cells({
        32: [(1.0, 0.5)],  # strips win
        64: [(1.0, 0.8), (1.0, 1.15)],  # strips lose 15% on one scene, plain 25% on the other: strips
        128: [(1.0, 0.95), (1.0, 1.12)],  # strips lose 12%, plain 5%: plain
        256: [(1.0, 1.01), (1.0, 0.995)],  # a tie (both within TOLERANCE): the smaller sum, plain (2.0 vs 2.005)
        1024: [(2.0, 1.0)],
    }))
    got = [(r["face_min"], r["face_max"], r["kernel"]) for r in rows]
    # bounds at the geometric mean of neighbouring measured sizes: isqrt(64*128) = 90, isqrt(256*1024) = 512
    assert got == [(1, 90, "strips"), (91, 512, "plain"), (513, None, "strips")]
    assert rows[0]["measured"]["64"]["worst_loss"] == {"plain": 0.25, "strips": 0.15}
    table = KT.KernelTable(json.loads(KT.table_json(rows, {})))
    assert [table.pick("gpu", "raster", f).kernel for f in (1, 90, 91, 300, 512, 513, 4096)] == \
        ["strips", "strips", "plain", "plain", "plain", "strips", "strips"]


def test_cells_missing_a_kernel_are_left_out():
    cells = _cells({64: [(1.0, 0.5)]}) + [KT.Cell("gpu", "raster", "lonely", 1, 128, "strips", 0.1)]
    assert [r["face_max"] for r in KT.choose_rows(cells)] == [None]
    with pytest.raises(ValueError):
        KT.choose_rows([KT.Cell("gpu", "raster", "s", 1, 64, "splat", 1.0)])


def test_device_classes():
    assert KT.device_class(0x10DE) == "nvidia" and KT.device_class(0x1002) == "amd"
    assert KT.device_class(0x10DE, is_cpu=True) == "cpu" and KT.device_class(0xABCD) == "gpu"
    assert KT.device_class(name="llvmpipe (LLVM 15.0.6, 256 bits)") == "cpu"
    assert KT.device_class(name="NVIDIA H200") == "nvidia" and KT.device_class(name="Mystery 9000") == "gpu"
    ctx = get_context()
    assert KT.context_class(ctx) == "cpu" if ctx.is_cpu else KT.context_class(ctx) in set(KT.VENDORS.values()) | {"gpu"}


def test_bad_tables_are_refused_and_an_unreadable_one_falls_back(tmp_path):
    row = {"device": "gpu", "stage": "raster", "face_min": 1, "face_max": None, "kernel": "strips"}
    with pytest.raises(ValueError):
        KT.KernelTable({"format": 1, "rows": [dict(row, kernel="fast")]})
    with pytest.raises(ValueError):
        KT.KernelTable({"format": 1, "rows": [row, dict(row, face_min=64)]})  # overlapping
    with pytest.raises(ValueError):
        KT.KernelTable({"format": 2, "rows": []})
    bad = tmp_path / "kernel_table.json"
    bad.write_text('{"format": 1, "rows": [')
    with pytest.warns(RuntimeWarning, match="fallback"):
        table = KT.load(str(bad))
    assert table.pick("cpu", "raster", 64) == KT.Pick("plain", "fallback: no raster row for 'cpu' at 64")
    assert table.pick("nvidia", "emit", 64).kernel == "slot"


def _table(kernels: dict) -> KT.KernelTable:
    """A table whose only rows give this device's class ``kernels`` ({stage: kernel}) at every size."""
    cls = KT.context_class(get_context())
    return KT.KernelTable({"format": 1, "rows": [
        {"device": cls, "stage": st, "face_min": 1, "face_max": None, "kernel": k} for st, k in kernels.items()]})


def test_renderer_takes_the_tables_kernels_and_switches_override_them(monkeypatch):
    ctx = get_context()
    batch = ViewBatch.cubemap(np.zeros(3), 64)
    monkeypatch.setattr(KT, "load", lambda path=KT.TABLE_PATH: _table({"raster": "strips", "emit": "slot"}))
    k = R.batch_kernels(ctx, batch, 6 * 16)
    assert (k["raster"], k["emit"]) == ("gs_raster_conic_strips", "gs_emit")
    assert "table" in k["raster_source"]
    monkeypatch.setattr(R, "RASTER_STRIPS", False)
    monkeypatch.setattr(R, "EMIT_PER_SPLAT", True)
    k = R.batch_kernels(ctx, batch, 6 * 16)
    assert (k["raster"], k["emit"], k["raster_source"]) == ("gs_raster_conic", "gs_emit_per_splat",
                                                            "renderer.RASTER_STRIPS")
    # the per-splat emit's loop bound holds whatever the table or the switch says
    assert R.batch_kernels(ctx, batch, R.EMIT_PER_SPLAT_MAX_TILES + 1)["emit"] == "gs_emit"
    monkeypatch.setattr(KT, "load", lambda path=KT.TABLE_PATH: KT.KernelTable({"format": 1, "rows": []}))
    monkeypatch.setattr(R, "RASTER_STRIPS", None)
    monkeypatch.setattr(R, "EMIT_PER_SPLAT", None)
    k = R.batch_kernels(ctx, ViewBatch.pinhole(np.zeros(3), [1, 0, 0], 60, 1920, 1080), 120 * 68)
    assert (k["raster"], k["emit"]) == ("gs_raster", "gs_emit") and k["raster_source"].startswith("fallback")


def test_the_default_is_the_committed_tables_pick():
    ctx = get_context()
    table, cls = KT.load(), KT.context_class(ctx)
    assert R.RASTER_STRIPS is None and R.EMIT_PER_SPLAT is None
    for face in (32, 64, 256, 1024):
        assert R.raster_strips(ctx, face) == (table.pick(cls, "raster", face).kernel == "strips")
        assert R.emit_per_splat(ctx, 6 * (face // 16) ** 2, face) == (table.pick(cls, "emit", face).kernel == "splat")


CASES = {
    "shell64": lambda: (_small_shell(), ViewBatch.cubemap(np.array([0.3, 0.2, -0.1]), 64)),  # conic kernels
    "mixed32": lambda: (_mixed(), ViewBatch.cubemap(np.array([0.05, -0.1, 0.02]), 32)),
    "camera": lambda: (_wall(), ViewBatch.pinhole(np.zeros(3), np.array([20.0, 0, 0]), 6.0, 160, 90)),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_images_are_the_same_whichever_kernels_the_table_picks(case, monkeypatch):
    scene, batch = CASES[case]()
    r = R.SplatRenderer(scene, get_context())
    try:
        images, depths, used = [], [], set()
        for raster in ("plain", "strips"):
            for emit in ("slot", "splat"):
                monkeypatch.setattr(KT, "load", lambda path=KT.TABLE_PATH, k={"raster": raster, "emit": emit}:
                                    _table(k))
                res = r.render(batch, depth=True)  # one renderer: each pick records a program of its own
                images.append(np.stack(res.images))
                depths.append(np.stack(res.depths))
                used.add((r.kernels["raster"], r.kernels["emit"]))
        assert len(used) == 4
        assert images[0][..., 3].mean() > 0.005
        for im, z in zip(images[1:], depths[1:]):
            np.testing.assert_array_equal(im, images[0])
            np.testing.assert_array_equal(z, depths[0])
    finally:
        r.close()


def test_ab_variants_time_every_choice():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        peer = _bench("peer_bench")
    assert sorted(peer.TABLE_VARIANTS.values()) == sorted((st, k) for st, ch in KT.CHOICES.items() for k in ch)
    ctx = get_context()
    for v, (stage, kernel) in peer.TABLE_VARIANTS.items():
        switches = peer.VARIANTS[v][1]
        saved = {k: getattr(R, k) for k in switches}
        try:
            for k, x in switches.items():
                setattr(R, k, x)
            assert R.kernel_picks(ctx, 64)[stage].kernel == kernel
        finally:
            for k, x in saved.items():
                setattr(R, k, x)
