"""Decode time and peak memory of each compressed splat format for 1M splats (SH degree 3 where the format has SH).

Makes one random scene (core.synthetic.random_scene), writes it with our writers to /tmp (SuperSplat compressed PLY,
SPZ v2, v3, v4, .splat, SOG, GLB with KHR_gaussian_splatting, .ksplat modes 0 and 1), then decodes each file in fresh subprocesses so the numbers are clean: one run for wall
time (best of ``--repeat``) and peak RSS delta (VmHWM after the read minus VmRSS before it, imports done), one under
tracemalloc for the peak of Python/numpy allocations. Files are in the page cache (just written), so times are
warm-cache times. The "scene" column is the size of the SplatScene arrays the reader returns, the floor for any
reader. Prints one line per format.

    .venv/bin/python benchmarks/format_decode.py [--n 1000000] [--degree 3] [--repeat 3]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CHILD = r"""
import json, resource, sys, time, tracemalloc
from gs_ibl_addon.core.formats import read_scene
path, traced = sys.argv[1], sys.argv[2] == "1"
def kib(key):
    try:
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) for l in f if l.startswith(key + ":"))
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
import numpy, plyfile, zstandard, gzip, zipfile, OpenImageIO  # imports outside the measured span
from gs_ibl_addon.core.formats import compressed_ply, spz, splat, sog, gltf, ksplat, webp
before = kib("VmRSS")
if traced:
    tracemalloc.start()
t = time.perf_counter()
scene = read_scene(path)
wall = time.perf_counter() - t
nbytes = sum(a.nbytes for a in (scene.positions, scene.scales, scene.rotations, scene.opacities, scene.sh))
out = {"wall_s": wall, "count": scene.count, "rss_delta_kib": kib("VmHWM") - before, "scene_bytes": nbytes}
if traced:
    out["traced_peak_bytes"] = tracemalloc.get_traced_memory()[1]
print(json.dumps(out))
"""


def measure(path: str, traced: bool) -> dict:
    """Decode ``path`` with read_scene in a fresh process: wall time, count, peak RSS delta (and tracemalloc peak)."""
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    res = subprocess.run([sys.executable, "-c", CHILD, path, "1" if traced else "0"], env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--degree", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", help="comma-separated parts of format names to run (e.g. sog,glb,ksplat)")
    args = ap.parse_args()
    sys.path.insert(0, ROOT)
    from gs_ibl_addon.core.formats.compressed_ply import write_compressed_ply
    from gs_ibl_addon.core.formats.gltf import write_glb
    from gs_ibl_addon.core.formats.ksplat import write_ksplat
    from gs_ibl_addon.core.formats.sog import write_sog
    from gs_ibl_addon.core.formats.splat import write_splat
    from gs_ibl_addon.core.formats.spz import write_spz
    from gs_ibl_addon.core.synthetic import random_scene

    scene = random_scene(args.n, seed=1, sh_degree=args.degree)
    stem = f"/tmp/gs_ibl_fmt_{args.n}_sh{args.degree}"
    writers = {
        "compressed.ply": lambda p: write_compressed_ply(p, scene),
        "spz v2": lambda p: write_spz(p, scene, version=2),
        "spz v3": lambda p: write_spz(p, scene, version=3),
        "spz v4": lambda p: write_spz(p, scene, version=4),
        ".splat (SH 0)": lambda p: write_splat(p, scene),
        "sog (SH 0)": lambda p: write_sog(p, scene),
        "glb": lambda p: write_glb(p, scene),
        "ksplat mode 0": lambda p: write_ksplat(p, scene, 0),
        "ksplat mode 1": lambda p: write_ksplat(p, scene, 1),
    }
    suffix = {"compressed.ply": ".compressed.ply", ".splat (SH 0)": ".splat", "sog (SH 0)": ".sog", "glb": ".glb",
              "ksplat mode 0": ".m0.ksplat", "ksplat mode 1": ".m1.ksplat"}
    only = set(args.only.split(",")) if args.only else None
    for name, write in writers.items():
        if only and not any(o in name for o in only):
            continue
        path = stem + suffix.get(name, f".{name.replace(' ', '')}.spz")
        write(path)
        size = os.path.getsize(path)
        runs = [measure(path, traced=False) for _ in range(args.repeat)]
        best = min(runs, key=lambda r: r["wall_s"])
        rss = max(r["rss_delta_kib"] for r in runs) * 1024
        traced = measure(path, traced=True)["traced_peak_bytes"]
        print(f"{name:15s} {best['count']} splats  file {size / 2**20:7.1f} MiB  decode {best['wall_s']:6.2f} s  "
              f"peak RSS +{rss / 2**20:6.0f} MiB  tracemalloc peak {traced / 2**20:6.0f} MiB  "
              f"scene {best['scene_bytes'] / 2**20:5.0f} MiB", flush=True)


if __name__ == "__main__":
    main()
