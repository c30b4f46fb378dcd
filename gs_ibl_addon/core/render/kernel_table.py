"""Which raster and emit kernels a device takes, from measurements: render/kernel_table.json.

The renderer has two ways of doing two of its stages, each drawing the same images bit for bit
(tests/test_raster_strips.py, tests/test_emit.py):
  raster  "plain"  gs_raster / gs_raster_conic: every pixel of a tile steps over all of the tile's pairs
          "strips" gs_raster_strips / gs_raster_conic_strips: each strip of two pixel rows steps only over the pairs
                   whose footprint can reach it
  emit    "slot"   gs_emit_owners + gs_emit: one thread per instance slot, which finds the splat owning it
          "splat"  gs_emit_per_splat: one thread per splat writes all of its slots
Which is faster depends on the device and the frame, so neither is hand-set: a benchmark times both in the same
process (benchmarks/peer_bench.py or raster_ab_bench.py with A/B variants) and ``raster_ab_bench.py table`` turns
those timings into the table by the rule below (``choose_rows``); the renderer reads the table once and looks up
(device class, stage, frame size) for every batch shape it records (``pick``).

The rule, per device class, stage and measured frame size f (a cube face's side; a camera frame's larger side):
over the cells measured at f (scene x splat count, both kernels timed in one process), each kernel's worst loss
is max over cells of its GPU time / the faster kernel's - 1. The kernel with the smaller worst loss is taken (so a
kernel that loses by more than TOLERANCE in some cell is never taken where the other loses by less everywhere);
worst losses within TOLERANCE of each other are a tie, which the smaller summed time decides. Each measured size
holds the sizes nearest to it (bounds at the geometric mean of two neighbours; the smallest from 1, the largest up
without bound), and neighbours with the same kernel become one row.

A device class with no rows for a stage takes the table's "fallback" kernel for it (plain raster, per-slot emit:
the kernels every GPU ran before the strips and the per-splat emit existed); a missing or unreadable table does the
same for every class, with one warning. Constraints that are about correctness, not speed, stay in the renderer
(the per-splat emit's loop bound on lavapipe: renderer.EMIT_PER_SPLAT_MAX_TILES).
"""
from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass
from functools import lru_cache

TABLE_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "kernel_table.json")
FORMAT = 1
# What each stage's choices are and the kernels (core/vk/kernels.py KERNELS) each one dispatches; the renderer,
# the benchmarks' A/B variants and tests/test_kernel_table.py all read this one declaration.
CHOICES: dict[str, dict[str, tuple[str, ...]]] = {
    "raster": {"plain": ("gs_raster", "gs_raster_conic"), "strips": ("gs_raster_strips", "gs_raster_conic_strips")},
    "emit": {"slot": ("gs_emit_owners", "gs_emit"), "splat": ("gs_emit_per_splat",)},
}
FALLBACK = {"raster": "plain", "emit": "slot"}  # used when the table cannot be read
TOLERANCE = 0.02  # worst losses closer than this are a tie (the run-to-run spread of a GPU's medians)
# Vulkan vendor IDs (VkPhysicalDeviceProperties.vendorID) -> device class; a CPU device (lavapipe, SwiftShader) is
# "cpu" whoever made it, and any other vendor "gpu".
VENDORS = {0x10DE: "nvidia", 0x1002: "amd", 0x1022: "amd", 0x8086: "intel", 0x106B: "apple", 0x13B5: "arm",
           0x5143: "qualcomm"}
_NAME_HINTS = (("llvmpipe", "cpu"), ("lavapipe", "cpu"), ("swiftshader", "cpu"), ("softpipe", "cpu"),
               ("nvidia", "nvidia"), ("geforce", "nvidia"), ("quadro", "nvidia"), ("amd", "amd"), ("radeon", "amd"),
               ("intel", "intel"), ("apple", "apple"), ("mali", "arm"), ("adreno", "qualcomm"))


def device_class(vendor_id: int | None = None, is_cpu: bool = False, name: str = "") -> str:
    """The table's device class: "cpu" for a CPU device, else by Vulkan vendor ID, else (benchmark CSVs, which
    record only the device's name) by the name; "gpu" for any other device."""
    if is_cpu:
        return "cpu"
    if vendor_id is not None:
        return VENDORS.get(int(vendor_id), "gpu")
    low = name.lower()
    return next((cls for hint, cls in _NAME_HINTS if hint in low), "gpu")


def context_class(ctx) -> str:
    """The device class of a VulkanContext."""
    if ctx.is_cpu:
        return "cpu"
    props = ctx.vk.vkGetPhysicalDeviceProperties(ctx.physical_device)
    return device_class(int(props.vendorID))


@dataclass(frozen=True)
class Row:
    device: str
    stage: str
    face_min: int
    face_max: int | None  # None: no upper bound
    kernel: str

    def holds(self, device: str, stage: str, face: int) -> bool:
        return (self.device == device and self.stage == stage and self.face_min <= face
                and (self.face_max is None or face <= self.face_max))


@dataclass(frozen=True)
class Pick:
    kernel: str  # a CHOICES[stage] key
    source: str  # the row it came from, or why the fallback


class KernelTable:
    def __init__(self, data: dict, path: str = "") -> None:
        self.path = path
        if data.get("format") != FORMAT:
            raise ValueError(f"kernel table format {data.get('format')!r}, expected {FORMAT}")
        fallback = data.get("fallback", {})
        self.fallback = {stage: fallback.get(stage, FALLBACK[stage]) for stage in CHOICES}
        self.rows: list[Row] = []
        for d in data.get("rows", []):
            row = Row(str(d["device"]), str(d["stage"]), int(d["face_min"]),
                      None if d.get("face_max") is None else int(d["face_max"]), str(d["kernel"]))
            if row.stage not in CHOICES or row.kernel not in CHOICES[row.stage]:
                raise ValueError(f"kernel table row {d}: stage and kernel must be one of {CHOICES}")
            if row.face_min < 1 or (row.face_max is not None and row.face_max < row.face_min):
                raise ValueError(f"kernel table row {d}: face range is empty")
            self.rows.append(row)
        for stage, kernel in self.fallback.items():
            if kernel not in CHOICES[stage]:
                raise ValueError(f"kernel table fallback {stage}: {kernel!r} is not one of {list(CHOICES[stage])}")
        for a in self.rows:  # one row for any (device, stage, face)
            for b in self.rows:
                if a is not b and a.device == b.device and a.stage == b.stage and \
                        a.face_min <= (b.face_max or math.inf) and b.face_min <= (a.face_max or math.inf):
                    raise ValueError(f"kernel table rows overlap: {a} and {b}")

    def pick(self, device: str, stage: str, face: int) -> Pick:
        """The kernel for ``stage`` on a ``device``-class device drawing frames whose larger side is ``face``."""
        for row in self.rows:
            if row.holds(device, stage, int(face)):
                top = "up" if row.face_max is None else str(row.face_max)
                return Pick(row.kernel, f"{os.path.basename(self.path) or 'table'}: {device} {stage} "
                                        f"{row.face_min}-{top}")
        return Pick(self.fallback[stage], f"fallback: no {stage} row for {device!r} at {face}")

    def devices(self) -> list[str]:
        return sorted({r.device for r in self.rows})


@lru_cache(maxsize=None)
def load(path: str = TABLE_PATH) -> KernelTable:
    """The table at ``path``, read once; an unreadable one warns and gives the fallback everywhere."""
    try:
        with open(path) as f:
            return KernelTable(json.load(f), path)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        warnings.warn(f"kernel table {path} unreadable ({exc}): every device takes the fallback kernels "
                      f"{FALLBACK}", RuntimeWarning, stacklevel=2)
        return KernelTable({"format": FORMAT, "fallback": dict(FALLBACK), "rows": []}, path)


# ---- the writer's rule (benchmarks/raster_ab_bench.py table) ----------------------------------------------------

@dataclass(frozen=True)
class Cell:
    """One measurement: ``ms`` of the frame with ``kernel`` for ``stage``, everything else the same."""
    device: str
    stage: str
    scene: str
    splats: int
    face: int
    kernel: str
    ms: float


def face_decisions(cells: list[Cell], tolerance: float = TOLERANCE) -> dict[tuple[str, str, int], dict]:
    """Per (device, stage, measured face): the kernel the rule takes and why (module docstring). Cells whose
    (scene, splats) lack a timing of every kernel of the stage are left out."""
    groups: dict[tuple[str, str, int], dict[tuple[str, int], dict[str, float]]] = {}
    for c in cells:
        if c.kernel not in CHOICES[c.stage]:
            raise ValueError(f"{c}: {c.stage} kernels are {list(CHOICES[c.stage])}")
        groups.setdefault((c.device, c.stage, c.face), {}).setdefault((c.scene, c.splats), {})[c.kernel] = c.ms
    out = {}
    for key, by_cell in sorted(groups.items()):
        kernels = list(CHOICES[key[1]])
        full = {k: v for k, v in by_cell.items() if all(x in v for x in kernels)}
        if not full:
            continue
        worst = {k: max(v[k] / min(v.values()) - 1.0 for v in full.values()) for k in kernels}
        total = {k: sum(v[k] for v in full.values()) for k in kernels}
        a, b = sorted(kernels, key=lambda k: worst[k])
        if worst[b] - worst[a] <= tolerance:
            a = min(kernels, key=lambda k: total[k])
        out[key] = {"kernel": a, "cells": len(full), "worst_loss": {k: round(worst[k], 3) for k in kernels},
                    "total_ms": {k: round(total[k], 3) for k in kernels}}
    return out


def choose_rows(cells: list[Cell], tolerance: float = TOLERANCE) -> list[dict]:
    """The table's rows for ``cells``: face_decisions spread over face ranges, equal neighbours merged."""
    decided = face_decisions(cells, tolerance)
    rows = []
    for device, stage in sorted({(d, s) for d, s, _ in decided}):
        faces = sorted(f for d, s, f in decided if (d, s) == (device, stage))
        for i, f in enumerate(faces):
            dec = decided[device, stage, f]
            lo = 1 if i == 0 else math.isqrt(faces[i - 1] * f) + 1
            hi = None if i == len(faces) - 1 else math.isqrt(f * faces[i + 1])
            last = rows[-1] if rows else None
            if last and (last["device"], last["stage"], last["kernel"]) == (device, stage, dec["kernel"]):
                last["face_max"] = hi
                last["measured"][str(f)] = dec
                continue
            rows.append({"device": device, "stage": stage, "face_min": lo, "face_max": hi, "kernel": dec["kernel"],
                         "measured": {str(f): dec}})
    return rows


def table_json(rows: list[dict], sources: dict[str, list[str]], tolerance: float = TOLERANCE,
               fallback: dict | None = None) -> str:
    """The table file's text: one row a line (diffs stay readable)."""
    head = {"format": FORMAT,
            "about": "Raster and emit kernels per device class and frame size (a cube face's side, a camera frame's "
                     "larger side), from A/B timings: written by benchmarks/raster_ab_bench.py table, read by "
                     "gs_ibl_addon/core/render/kernel_table.py (its docstring has the rule).",
            "tolerance": tolerance, "fallback": fallback or dict(FALLBACK), "sources": sources}
    text = json.dumps(head, indent=1)[:-2] + ',\n "rows": [\n'
    text += ",\n".join("  " + json.dumps(r, sort_keys=False) for r in rows)
    return text + "\n ]\n}\n"
