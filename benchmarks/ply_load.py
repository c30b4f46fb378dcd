"""Load time and peak memory of read_ply on a 1M-splat, SH degree 3 standard 3DGS PLY (248 bytes per splat).

Writes the file to /tmp once (random_scene + write_ply), then loads it in fresh subprocesses (format_decode's
measurement: wall time and peak RSS delta in one, tracemalloc peak in another). The file is in the page cache
(just written or read), so the time is a warm-cache time. Prints one line.

    .venv/bin/python benchmarks/ply_load.py [n_splats]
"""
from __future__ import annotations

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(HERE))

from format_decode import measure  # noqa: E402


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
    path = f"/tmp/gs_ibl_bench_{n}_sh3.ply"
    from gs_ibl_addon.core.formats.ply import write_ply
    from gs_ibl_addon.core.synthetic import random_scene
    if not os.path.exists(path) or os.path.getsize(path) < n * 248:
        write_ply(path, random_scene(n, seed=1, sh_degree=3))
    size = os.path.getsize(path)
    plain = measure(path, traced=False)
    traced = measure(path, traced=True)
    rss = plain["rss_delta_kib"] * 1024
    print(f"ply_load: {plain['count']} splats, file {size / 2**20:.1f} MiB, load {plain['wall_s']:.2f} s, "
          f"peak RSS delta {rss / 2**20:.1f} MiB ({rss / size:.2f}x file), "
          f"tracemalloc peak {traced['traced_peak_bytes'] / 2**20:.1f} MiB "
          f"({traced['traced_peak_bytes'] / size:.2f}x file)")


if __name__ == "__main__":
    main()
