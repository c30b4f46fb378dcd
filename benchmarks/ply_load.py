"""Load time and peak memory of read_ply on a 1M-splat, SH degree 3 standard 3DGS PLY (248 bytes per splat).

Writes the file to /tmp once (random_scene + write_ply), then loads it in fresh subprocesses so the numbers are
clean: one run for wall time and peak RSS delta (VmHWM after the load minus VmRSS before it, imports done;
ru_maxrss where there is no /proc), one
under tracemalloc for the peak of Python/numpy allocations. The file is in the page cache (just written or read),
so the time is a warm-cache time. Prints one line.

    .venv/bin/python benchmarks/ply_load.py [n_splats]
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CHILD = r"""
import json, resource, sys, time, tracemalloc
from gs_ibl_addon.core.formats.ply import read_ply
path, traced = sys.argv[1], sys.argv[2] == "1"
def kib(key):
    # VmHWM/VmRSS belong to this process image; ru_maxrss would carry the parent's peak across fork+exec.
    try:
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) for l in f if l.startswith(key + ":"))
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
before = kib("VmRSS")
if traced:
    tracemalloc.start()
t = time.perf_counter()
scene = read_ply(path)
wall = time.perf_counter() - t
out = {"wall_s": wall, "count": scene.count, "rss_delta_kib": kib("VmHWM") - before}
if traced:
    out["traced_peak_bytes"] = tracemalloc.get_traced_memory()[1]
print(json.dumps(out))
"""


def _child(path: str, traced: bool) -> dict:
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    res = subprocess.run([sys.executable, "-c", CHILD, path, "1" if traced else "0"], env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
    path = f"/tmp/gs_ibl_bench_{n}_sh3.ply"
    sys.path.insert(0, ROOT)
    from gs_ibl_addon.core.formats.ply import write_ply
    from gs_ibl_addon.core.synthetic import random_scene
    if not os.path.exists(path) or os.path.getsize(path) < n * 248:
        write_ply(path, random_scene(n, seed=1, sh_degree=3))
    size = os.path.getsize(path)
    plain = _child(path, traced=False)
    traced = _child(path, traced=True)
    rss = plain["rss_delta_kib"] * 1024
    print(f"ply_load: {plain['count']} splats, file {size / 2**20:.1f} MiB, load {plain['wall_s']:.2f} s, "
          f"peak RSS delta {rss / 2**20:.1f} MiB ({rss / size:.2f}x file), "
          f"tracemalloc peak {traced['traced_peak_bytes'] / 2**20:.1f} MiB "
          f"({traced['traced_peak_bytes'] / size:.2f}x file)")


if __name__ == "__main__":
    main()
