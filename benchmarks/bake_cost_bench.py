"""What the default bake costs against a 64^2 bake, and its true error (issue 22 goal 1), in one process.

Run: python benchmarks/bake_cost_bench.py [--repeats 3] [--truth-face 1024] [--out CSV]

Per scene (the bundled sample room, the guitar capture, a synthetic sun shell) and per setting, bake_probe from one
uploaded renderer as the command line's bake does (``default``: face size 0 and irradiance size 0, the tolerance
1%; ``64``: face size 64, irradiance 16), then write_probe's outputs to a temporary folder:

- ``bake_wall_ms`` (median of --repeats after one warm-up), ``write_wall_ms`` (the EXR, JSON and preview files),
  ``gpu_ms`` (render + filters from timestamps, all renders of the search), ``faces`` (per-face sizes);
- ``true_error``: relative RMS (pooled, as bake.relative_rms) of the irradiance against a --truth-face render
  (box-downsampled to 128^2 and integrated exactly), both read at the texel centres of a 16^2 cube;
- ``ratio``: the setting's bake + write wall time over the 64^2 bake's, in the same run.
The device, the date, the load and, on an NVIDIA GPU, the SM clock (held by a CUDA context: bench_common) are
written on every row. Prints a table; appends to --out (default docs/bench/bake_cost_<device>.csv).
"""
from __future__ import annotations

import argparse
import datetime
import os
import statistics
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_common import append_csv, gpu_clock, hold_gpu_clock  # noqa: E402
from gs_ibl_addon.core import cubemap  # noqa: E402
from gs_ibl_addon.core.bake import ProbeSettings, bake_probe, default_probe_position, relative_rms  # noqa: E402
from gs_ibl_addon.core.formats import read_scene  # noqa: E402
from gs_ibl_addon.core.probe import sample_cube_bilinear  # noqa: E402
from gs_ibl_addon.core.probe.result import write_probe  # noqa: E402
from gs_ibl_addon.core.render.renderer import SplatRenderer  # noqa: E402
from gs_ibl_addon.core.synthetic import BrightPatch, shell_scene  # noqa: E402

REPO = os.path.dirname(HERE)
SETTINGS = {"64": dict(face_size=64, irradiance_size=16), "default": dict(face_size=0, irradiance_size=0)}


def scenes() -> dict:
    guitar = read_scene(os.path.join(REPO, "tests", "data", "guitar.compressed.ply"))
    room = read_scene(os.path.join(REPO, "samples", "room.ply"))
    return {"sample room": (room, default_probe_position(room)),
            "guitar capture": (guitar, default_probe_position(guitar)),
            "sun shell": (shell_scene(BrightPatch(), 20_000, radius=5.0), np.zeros(3))}


def common(irradiance: np.ndarray) -> np.ndarray:
    return sample_cube_bilinear(np.asarray(irradiance, np.float64), cubemap.face_directions(16))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--truth-face", type=int, default=1024)
    ap.add_argument("--only", help="one scene's name")
    ap.add_argument("--out")
    a = ap.parse_args()
    keep = hold_gpu_clock()  # noqa: F841  (the CUDA context must live as long as the runs)
    rows = []
    for name, (scene, pos) in scenes().items():
        if a.only and a.only != name:
            continue
        with SplatRenderer(scene) as r:
            truth = bake_probe(scene, pos, ProbeSettings(face_size=a.truth_face, irradiance_size=16,
                                                         extra={"downsample_to": 128}), renderer=r)
            want = common(truth.irradiance)
            base = None
            for label, kw in SETTINGS.items():
                s = ProbeSettings(**kw)
                bake_probe(scene, pos, s, renderer=r)  # warm-up: pipelines, clocks
                bakes, writes, result = [], [], None
                for _ in range(a.repeats):
                    t = time.perf_counter()
                    result = bake_probe(scene, pos, s, renderer=r)
                    bakes.append(time.perf_counter() - t)
                    with tempfile.TemporaryDirectory() as out:
                        t = time.perf_counter()
                        write_probe(result, out)
                        writes.append(time.perf_counter() - t)
                tm = result.timings_ms
                gpu = tm.get("render_total", 0.0) + sum(tm.get(k, 0.0) for k in ("sh_project", "irradiance"))
                wall = statistics.median(bakes) + statistics.median(writes)
                base = wall if label == "64" else base
                row = {"date": datetime.date.today().isoformat(), "device": r.ctx.device_name,
                       "sm_clock_mhz": gpu_clock(), "load1": round(os.getloadavg()[0], 2), "scene": name,
                       "splats": scene.count, "setting": label,
                       "faces": "/".join(map(str, result.settings.get("face_sizes") or
                                             [result.settings["face_size"]] * 6)),
                       "irradiance_size": result.settings["irradiance_size"],
                       "bake_wall_ms": round(1e3 * statistics.median(bakes), 1),
                       "write_wall_ms": round(1e3 * statistics.median(writes), 1), "gpu_ms": round(gpu, 2),
                       "true_error": round(relative_rms(common(result.irradiance), want), 5),
                       "estimated_error": result.settings.get("tolerance_plan", {}).get("estimated_error", ""),
                       "ratio": round(wall / base, 2)}
                rows.append(row)
                print(" | ".join(f"{k} {v}" for k, v in row.items() if k not in ("date", "device")), flush=True)
    device = rows[0]["device"].split(" (")[0].lower().replace(" ", "-") if rows else "none"
    append_csv(a.out or os.path.join(REPO, "docs", "bench", f"bake_cost_{device}.csv"), rows)


if __name__ == "__main__":
    main()
