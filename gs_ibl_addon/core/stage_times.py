"""Wall and GPU time per stage of a bake, and the submissions each made, from a Vulkan context's TransferStats.

A stage's GPU time is that of the submissions waited for inside it (a render submitted without waiting counts
where the filter behind it is waited for); submissions recorded without timestamps count only while the context's
``stamp_all`` is on (benchmarks). host = wall - GPU is what the bake costs beyond the device's work.

They travel in a result's ``timings_ms`` under ``stage:<name>:wall``, ``stage:<name>:gpu`` and
``stage:<name>:submits`` (one flat dict of numbers, as probe.json stores it), in the order the stages ran.
"""
from __future__ import annotations

import contextlib
import time
from typing import Iterator

PREFIX = "stage:"
FIELDS = ("wall", "gpu", "submits")


class StageTimes:
    """``with times.stage("search"): ...`` adds the block's wall time, GPU time and submissions to ``timings``."""

    def __init__(self, ctx, timings: dict[str, float] | None = None) -> None:
        self.ctx = ctx
        self.timings: dict[str, float] = {} if timings is None else timings

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        stats = self.ctx.stats if self.ctx is not None else None
        before = stats.snapshot() if stats is not None else {}
        t0 = time.perf_counter()
        try:
            yield
        finally:
            wall = (time.perf_counter() - t0) * 1e3
            moved = stats.since(before) if stats is not None else {}
            add(self.timings, name, wall, moved.get("gpu_ms", 0.0), moved.get("submits", 0))


def add(timings: dict[str, float], name: str, wall_ms: float, gpu_ms: float = 0.0, submits: int = 0) -> None:
    """Add one stage's times to ``timings`` (a stage met again adds up)."""
    for field, value in zip(FIELDS, (wall_ms, gpu_ms, submits)):
        key = f"{PREFIX}{name}:{field}"
        timings[key] = timings.get(key, 0) + value


def stages(timings: dict[str, float]) -> dict[str, dict[str, float]]:
    """{stage: {"wall", "gpu", "host", "submits"}} from ``timings``, in the order the stages ran."""
    out: dict[str, dict[str, float]] = {}
    for key, value in timings.items():
        if not key.startswith(PREFIX):
            continue
        name, _, field = key[len(PREFIX):].rpartition(":")
        out.setdefault(name, {f: 0.0 for f in FIELDS})[field] = value
    for row in out.values():
        row["host"] = max(0.0, row["wall"] - row["gpu"])
    return out


def stage_text(timings: dict[str, float]) -> str:
    """One line: each stage's wall / GPU ms and submissions, and their sum (empty when none was timed)."""
    rows = stages(timings)
    if not rows:
        return ""
    parts = [f"{name} {r['wall']:.1f}/{r['gpu']:.1f} ({int(r['submits'])})" for name, r in rows.items()]
    wall, gpu = sum(r["wall"] for r in rows.values()), sum(r["gpu"] for r in rows.values())
    subs = int(sum(r["submits"] for r in rows.values()))
    return (f"stages, wall/GPU ms (submissions): {', '.join(parts)}; all {wall:.1f}/{gpu:.1f} ({subs}), "
            f"host {max(0.0, wall - gpu):.1f} ms")
