"""Chart of docs/bench/renderer.csv: GPU time per cubemap against splat count, one line per face size, with the
thesis's RTX 3070 cubemap figures for reference. Writes docs/renderer-scaling.png."""
from __future__ import annotations

import csv
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
# The thesis (Univ. Vienna, 2026), table 4: six 1024^2 faces, RTX 3070.
THESIS_1024 = [(50_000, 3.58), (6_000_000, 17.80)]


def main(csv_path: str = os.path.join(HERE, "..", "docs", "bench", "renderer.csv"),
         out: str = os.path.join(HERE, "..", "docs", "renderer-scaling.png")) -> None:
    rows = list(csv.DictReader(open(csv_path)))
    devices = sorted({r["device"] for r in rows})
    fig, axes = plt.subplots(1, len(devices), figsize=(6.5 * len(devices), 4.6), squeeze=False)
    for ax, dev in zip(axes[0], devices):
        by_face = defaultdict(list)
        for r in rows:
            if r["device"] == dev:
                by_face[int(r["face"])].append((int(r["splats"]), float(r["total_ms"])))
        for face in sorted(by_face):
            pts = sorted(by_face[face])
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=f"six {face}\u00b2 faces")
        ax.plot([p[0] for p in THESIS_1024], [p[1] for p in THESIS_1024], "k*--", ms=10,
                label="thesis, RTX 3070, six 1024\u00b2 faces")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("splats")
        ax.set_ylabel("cubemap GPU time, ms (timestamps, median)")
        date = next(r["date"] for r in rows if r["device"] == dev)
        ax.set_title(f"{dev} ({date})", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("gs-ibl: one batched render of a probe's six cube faces", fontsize=11)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(*sys.argv[1:])
