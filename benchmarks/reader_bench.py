"""PLY readers against their peers, in one run (issue 23, "Fast readers"): a 1M-splat SH-3 standard 3DGS PLY,
binary and ASCII (written once by write_ply under /tmp), read by

  here (this venv: bpy 4.2/5.0's numpy 1.26): plyfile's pure-Python ASCII reader, our ASCII read, our binary read;
  in the trixie root (bpy 5.3, numpy 2.x): Blender's own `bpy.ops.wm.ply_import` of both files, and our whole
  native import of both (read_scene + create_splat_object(native=True): a Gaussian-splat Point Cloud).

Each as min / median of a few runs (warm page cache), with the ratio against its peer measured in the same run.
The machine is shared: the load average is printed and recorded; ratios matter more than absolute times.
The files are undeclared (colour space sRGB), as trainers write them, so our import converts no colours.

Run:  .venv/bin/python benchmarks/reader_bench.py [--n 1000000] [--runs 3] [--plyfile-runs 1] [--no-blender]
Needs the trixie root for the Blender rows (scripts/blender_roots.sh ensure trixie). Prints a markdown table and
appends its rows to docs/bench/readers.csv. Inside the root this file runs with --in-blender ARGS.json.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, ".."))
ROOTS_SH = os.path.join(REPO, "scripts", "blender_roots.sh")
CSV = os.path.join(REPO, "docs", "bench", "readers.csv")
MARK = "reader_bench result: "  # Blender prints its own lines too


def timed(fn, runs: int, between=None) -> list[float]:
    out = []
    for _ in range(runs):
        if between is not None:
            between()
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


# ------------------------------------------------------------------------------------------------ inside Blender

def in_blender(args: dict) -> dict:
    sys.path[:0] = [args["plyfile_dir"], "/src"]  # plyfile: what the extension's zip ships as a wheel
    import bpy
    import numpy as np

    from gs_ibl_addon.blender.splats.object import create_splat_object
    from gs_ibl_addon.core.formats import read_scene

    def clear() -> None:
        for o in list(bpy.context.view_layer.objects.selected):
            o.select_set(False)
        bpy.context.view_layer.objects.active = None
        for o in list(bpy.data.objects):
            bpy.data.objects.remove(o)
        for coll in (bpy.data.pointclouds, bpy.data.meshes):
            for d in list(coll):
                coll.remove(d)

    clear()
    res = {"blender": bpy.app.version_string, "numpy": np.__version__}
    for kind, path in args["files"].items():
        res[f"blender {kind}"] = timed(lambda p=path: bpy.ops.wm.ply_import(filepath=p), args["runs"], clear)
        n = len(bpy.data.pointclouds[0].points)
        res[f"ours native {kind}"] = timed(
            lambda p=path: create_splat_object(bpy.context, read_scene(p), "bench", native=True), args["runs"], clear)
        assert len(bpy.data.pointclouds[0].points) == n, "our import and Blender's differ in count"
    clear()
    return res


def run_in_root(files: dict[str, str], runs: int) -> dict:
    root = subprocess.run(["bash", ROOTS_SH, "path", "trixie"], capture_output=True, text=True, check=True).stdout.strip()
    if subprocess.run(["bash", ROOTS_SH, "ready", "trixie"], check=False).returncode != 0:
        raise SystemExit("the bpy 5.3 root is not made: scripts/blender_roots.sh ensure trixie")
    inner = "/tmp/gs_ibl_reader_bench"
    host = root + inner
    os.makedirs(host, exist_ok=True)
    import plyfile
    shutil.copy(plyfile.__file__, host)
    inner_files = {}
    for kind, path in files.items():
        dst = os.path.join(host, os.path.basename(path))
        if not (os.path.exists(dst) and os.path.samefile(dst, path)):
            if os.path.exists(dst):
                os.remove(dst)
            try:
                os.link(path, dst)  # same file system: no copy of a 1.3 GB file
            except OSError:
                shutil.copy(path, dst)
        inner_files[kind] = f"{inner}/{os.path.basename(path)}"
    with open(os.path.join(host, "args.json"), "w") as f:
        json.dump({"files": inner_files, "runs": runs, "plyfile_dir": inner}, f)
    p = subprocess.run(["bash", ROOTS_SH, "chroot", "trixie", "env", "-C", "/src", "HOME=/tmp",
                        "/opt/bpy53/bin/python", "/src/benchmarks/reader_bench.py", "--in-blender",
                        f"{inner}/args.json"], capture_output=True, text=True, check=False)
    if p.returncode != 0:
        raise SystemExit(f"the bpy 5.3 run failed:\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}")
    return json.loads(next(ln for ln in p.stdout.splitlines() if ln.startswith(MARK))[len(MARK):])


# ----------------------------------------------------------------------------------------------------- the host

def make_files(n: int) -> dict[str, str]:
    sys.path.insert(0, REPO)
    from gs_ibl_addon.core.formats.ply import write_ply
    from gs_ibl_addon.core.synthetic import random_scene
    folder = "/tmp/gs_ibl_reader_bench"
    os.makedirs(folder, exist_ok=True)
    files = {"binary": f"{folder}/splats_{n}_sh3_bin.ply", "ascii": f"{folder}/splats_{n}_sh3_ascii.ply"}
    scene = None
    for kind, path in files.items():
        done = path + ".done"  # written last: a file cut off by an interrupted run is made again
        if os.path.exists(done) and os.path.exists(path):
            continue
        if scene is None:
            scene = random_scene(n, seed=1, sh_degree=3)
            scene.colour_space = "srgb"  # undeclared, as trainers' files are
        t0 = time.perf_counter()
        write_ply(path, scene, ascii=kind == "ascii")  # ASCII: plyfile's writer, "%.18g" (~2 min for 1M)
        print(f"wrote {path} ({os.path.getsize(path) / 2**20:.0f} MiB) in {time.perf_counter() - t0:.0f} s",
              flush=True)
        open(done, "w").close()
    return files


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--plyfile-runs", type=int, default=1, help="plyfile's ASCII read takes about a minute a run")
    ap.add_argument("--no-blender", action="store_true")
    ap.add_argument("--csv", default=CSV)
    ap.add_argument("--in-blender")
    a = ap.parse_args()
    if a.in_blender:
        with open(a.in_blender) as f:
            print(MARK + json.dumps(in_blender(json.load(f))), flush=True)
        return

    files = make_files(a.n)
    import numpy as np
    from plyfile import PlyData

    from gs_ibl_addon.core.formats import read_scene
    load0 = os.getloadavg()
    t: dict[str, list[float]] = {}
    t["ours ascii"] = timed(lambda: read_scene(files["ascii"]), a.runs)
    t["ours binary"] = timed(lambda: read_scene(files["binary"]), a.runs)
    t["plyfile ascii"] = timed(lambda: PlyData.read(files["ascii"])["vertex"].data, a.plyfile_runs)
    env = {"numpy_host": np.__version__}
    if not a.no_blender:
        res = run_in_root(files, a.runs)
        env.update(blender=res.pop("blender"), numpy_root=res.pop("numpy"))
        t.update(res)
    load1 = os.getloadavg()

    peers = {"ours ascii": "plyfile ascii", "ours native ascii": "blender ascii",
             "ours native binary": "blender binary"}
    date = datetime.date.today().isoformat()
    load = f"{load0[0]:.1f}-{load1[0]:.1f}"
    print(f"\n{a.n:,} splats, SH degree 3; {date}; {os.cpu_count()} cores; load average (1 min) {load}; "
          f"numpy {env['numpy_host']} here" + (f", bpy {env['blender']} with numpy {env['numpy_root']} in the root"
                                              if "blender" in env else "") + "\n")
    print("| reader | file | min s | median s | runs | peer | ratio (peer median / ours median) |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for name, ts in t.items():
        kind = "ascii" if name.endswith("ascii") else "binary"
        peer = peers.get(name)
        in_root = "native" in name or "blender" in name
        ratio = statistics.median(t[peer]) / statistics.median(ts) if peer in t else None
        print(f"| {name} | {kind} | {min(ts):.2f} | {statistics.median(ts):.2f} | {len(ts)} | {peer or ''} | "
              f"{f'{ratio:.2f}x' if ratio else ''} |")
        rows.append({"date": date, "machine": f"{os.cpu_count()}-core machine, lavapipe", "load": load, "splats": a.n,
                     "reader": name, "file": kind, "min_s": f"{min(ts):.3f}",
                     "median_s": f"{statistics.median(ts):.3f}", "runs": len(ts), "peer": peer or "",
                     "ratio": f"{ratio:.3f}" if ratio else "", "numpy": env.get("numpy_root" if in_root else "numpy_host"),
                     "blender": env.get("blender", "") if in_root else ""})
    if "blender ascii" in t:
        r = statistics.median(t["ours ascii"]) / statistics.median(t["blender ascii"])
        print(f"\nour ASCII read (here) / Blender's ASCII import: {r:.2f}x the time")
    os.makedirs(os.path.dirname(a.csv), exist_ok=True)
    new = not os.path.exists(a.csv)
    with open(a.csv, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        if new:
            w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
