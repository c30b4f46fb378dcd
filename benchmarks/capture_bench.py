"""Capture-sized scenes without freezing Blender (issue 23): before against after, in real Blenders.

    .venv/bin/python benchmarks/capture_bench.py [--sizes 1000000,3000000 | --quick] [--no-write]
    .venv/bin/python benchmarks/capture_bench.py --replot build/capture/results.json
    .venv/bin/python benchmarks/capture_bench.py --sizes 1000000 --thread-check build/capture/results.json

Inputs: capture-like PLYs (benchmarks/bench_common.bench_scene: SH degree 3, a 10 m box, splats smaller as there are
more; stored in a shuffled order as trained files are; binary little-endian: 248 MB per million splats), written
once under /tmp/gs_ibl_capture/ and reused. Two extension zips, each built by its own checkout's
scripts/build_extension.py with this venv's Python: "before" from commit 9ebe995 (before the jobs work; a git worktree
at /tmp/gsibl-before, made when missing and removed at the end unless --keep-worktree) and "after" from this
checkout. Each zip is installed by Blender's own installer into a fresh user directory
(tests/real_blender/test_matrix.py's Runner and _install), then:

- Blender 5.2's GUI under Xvfb (the sid root; benchmarks/capture_gui.py with tests/real_blender/gui_common.py):
  import (the file browser's path), Show Splats (first upload and first draw), orbit (frames per second and
  per-frame draw time of the overlay while the view turns), bake (a probe at the centre, face size 0, Lighting World
  Probe) and re-bake (the probe moved 0.25 m; then again with Show Splats off): wall seconds, the longest
  main-thread block (a 50 ms heartbeat timer's longest gap) and how many gaps exceeded 0.2 s. A stage that takes
  more than --stage-limit (300 s) is stopped and recorded as skipped, with the stages after it.
- the bpy 5.3 module headless (the trixie root; benchmarks/capture_headless.py): Blender's own PLY importer, our
  import as a mesh and as Blender's splats, bake and re-bake, in one process.
- --thread-check (after a run): benchmarks/trials/capture_thread_check.py, the same re-bake in bpy 5.3 inline and on a
  jobs.Runner worker, alternating (is a worker slower without any UI?), added to that run's results and outputs.

Sizes and variants run interleaved (1M before, 1M after, 3M before, ...) so load drift hits both alike; every row
carries os.getloadavg() at its start. Writes docs/bench/capture.csv, docs/img/capture_bench.png and the section
"Capture-sized scenes (issue 23)" of docs/benchmarks.md (replaced if there); raw results and Blender's logs in
build/capture/.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO / "tests" / "real_blender"))

INPUTS = Path("/tmp/gs_ibl_capture")
WORKTREE = Path("/tmp/gsibl-before")
BEFORE_COMMIT = "9ebe995"
WORK = REPO / "build" / "capture"
CSV_OUT = REPO / "docs" / "bench" / "capture.csv"
PNG_OUT = REPO / "docs" / "img" / "capture_bench.png"
MD = REPO / "docs" / "benchmarks.md"
SECTION = "## Capture-sized scenes (issue 23)"
DEVICE = "llvmpipe/lavapipe, 2-core machine"
VARIANTS = ("before", "after")
GUI_STAGES = ("import", "show", "orbit", "bake", "rebake", "rebake_hidden")
HEADLESS_STAGES = ("peer_import", "import_native", "import_mesh", "bake", "rebake")
STAGE_TEXT = {"import": "import (file browser)", "show": "Show Splats (upload + first draw)",
              "orbit": "orbit (overlay frames)", "bake": "bake", "rebake": "re-bake (probe moved)",
              "rebake_hidden": "re-bake, Show Splats off",
              "peer_import": "Blender's bpy.ops.wm.ply_import", "import_native": "our import, Blender's splats",
              "import_mesh": "our import, mesh", }
HEADLESS_TAG = "GSIBL-CAPTURE-HEADLESS"


def log(msg: str) -> None:
    print(f"[capture_bench {time.strftime('%H:%M:%S')}] {msg}", flush=True)


# ------------------------------------------------------------------------------------------------------- inputs

def ply_path(n: int) -> Path:
    return INPUTS / f"capture_{n}.ply"


def make_ply(n: int) -> Path:
    """bench_scene(n) in a shuffled order, binary PLY, written once (a file of the expected size is reused)."""
    path = ply_path(n)
    expect = n * 62 * 4  # 3 pos + 3 normal + 48 SH + opacity + 3 scale + 4 rot floats, plus the header
    if path.exists() and expect < path.stat().st_size < expect + 4096:
        return path
    import numpy as np
    from bench_common import bench_scene
    from gs_ibl_addon.core.formats.ply import write_ply
    t0 = time.perf_counter()
    scene = bench_scene(n)
    order = np.random.default_rng(0).permutation(n)  # trained files are unordered
    scene = scene.subset(order)
    INPUTS.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part")
    write_ply(str(tmp), scene)
    tmp.replace(path)
    log(f"wrote {path} ({path.stat().st_size / 1e6:.0f} MB) in {time.perf_counter() - t0:.1f} s")
    return path


def build_zips(keep_worktree: bool) -> dict:
    py = str(REPO / ".venv" / "bin" / "python")
    if not (WORKTREE / ".git").exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(WORKTREE), BEFORE_COMMIT], cwd=REPO, check=True,
                       capture_output=True)
    INPUTS.mkdir(parents=True, exist_ok=True)
    out = {}
    for variant, src in (("before", WORKTREE), ("after", REPO)):
        z = INPUTS / f"{variant}.zip"
        z.unlink(missing_ok=True)
        subprocess.run([py, "scripts/build_extension.py", "--output", str(z)], cwd=src, check=True,
                       capture_output=True, text=True)
        out[variant] = z
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "gs_ibl_addon"], cwd=REPO,
                           capture_output=True, text=True).stdout.split("\n")
    out["after_commit"] = head.strip()
    out["after_dirty"] = [x[3:] for x in dirty if x.strip()]
    if not keep_worktree:
        subprocess.run(["git", "worktree", "remove", "--force", str(WORKTREE)], cwd=REPO, capture_output=True)
    return out


# ------------------------------------------------------------------------------------------------------- runs

def _link(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)  # the roots live on this filesystem: no 744 MB copies
    except OSError:
        shutil.copy(src, dst)


KEEP = [WORK]  # where a run keeps its sessions' folders (a tagged repeat: a folder of its own)


def _keep(runner, name: str) -> Path:
    keep = KEEP[0] / name
    shutil.rmtree(keep, ignore_errors=True)
    shutil.copytree(runner.host, keep, ignore=shutil.ignore_patterns("home", "*.ply", "*.zip", "*.blend*"))
    return keep


def run_gui(matrix, variant: str, zip_path: Path, n: int, stage_limit: float) -> dict:
    entry = matrix.Entry("capture-gui", "sid", True, gui=True)
    runner = matrix.Runner(entry, None)
    name = f"gui-{variant}-{n}"
    t0 = time.perf_counter()
    try:
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        for f in (HERE / "capture_gui.py", REPO / "tests" / "real_blender" / "gui_common.py"):
            shutil.copy(f, runner.host / f.name)
        _link(ply_path(n), runner.host / "capture.ply")
        r = matrix._install(runner, str(runner.inner / "gs_ibl.zip"))
        if r.returncode != 0:
            return {"error": f"install failed: {r.stdout[-1500:]} {r.stderr[-1500:]}"}
        inner = runner.inner
        r = runner.run(matrix.xvfb_shell(f"blender --python {inner / 'capture_gui.py'} -- --out {inner / 'out'} "
                                         f"--ply {inner / 'capture.ply'} --stage-limit {stage_limit:.0f}"), "gui")
    finally:
        keep = _keep(runner, name)
        runner.close()
    out = keep / "out" / "capture.json"
    if not out.exists():
        return {"error": f"no capture.json (rc {r.returncode}); see {keep}/gui.log",
                "session_s": time.perf_counter() - t0}
    result = json.loads(out.read_text())
    result["session_s"] = time.perf_counter() - t0
    result["rc"] = r.returncode
    tracebacks = [x for x in (r.stdout + r.stderr).split("Traceback")[1:]]
    result["tracebacks"] = ["Traceback" + x[:1200] for x in tracebacks[:3]]
    return result


def run_headless(matrix, variant: str, zip_path: Path, n: int) -> dict:
    entry = matrix.Entry("capture-bpy53", "trixie", True, python="/opt/bpy53/bin/python")
    runner = matrix.Runner(entry, None)
    name = f"bpy53-{variant}-{n}"
    t0 = time.perf_counter()
    try:
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        shutil.copy(HERE / "capture_headless.py", runner.host / "capture_headless.py")
        _link(ply_path(n), runner.host / "capture.ply")
        (runner.host / "args.json").write_text(json.dumps({"ply": str(runner.inner / "capture.ply"),
                                                           "probe_move": 0.25}))
        r = matrix._install(runner, str(runner.inner / "gs_ibl.zip"))
        if r.returncode != 0:
            return {"error": f"install failed: {r.stdout[-1500:]} {r.stderr[-1500:]}"}
        r = runner.run([runner.python(), str(runner.inner / "capture_headless.py"), str(runner.inner / "args.json")],
                       "headless")
    finally:
        _keep(runner, name)
        runner.close()
    line = next((x for x in r.stdout.splitlines() if x.startswith(HEADLESS_TAG + " ")), None)
    if line is None:
        return {"error": f"no result (rc {r.returncode}): {r.stdout[-1500:]} {r.stderr[-2000:]}",
                "session_s": time.perf_counter() - t0}
    result = json.loads(line.split(" ", 1)[1])
    result["session_s"] = time.perf_counter() - t0
    return result


def run_thread_check(matrix, zip_path: Path, n: int, repeats: int) -> dict:
    """benchmarks/trials/capture_thread_check.py in bpy 5.3: the same re-bake inline and on a jobs.Runner worker."""
    entry = matrix.Entry("capture-thread", "trixie", True, python="/opt/bpy53/bin/python")
    runner = matrix.Runner(entry, None)
    try:
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        shutil.copy(HERE / "trials" / "capture_thread_check.py", runner.host / "capture_thread_check.py")
        _link(ply_path(n), runner.host / "capture.ply")
        (runner.host / "args.json").write_text(json.dumps({"ply": str(runner.inner / "capture.ply"),
                                                           "repeats": repeats}))
        r = matrix._install(runner, str(runner.inner / "gs_ibl.zip"))
        if r.returncode != 0:
            return {"error": f"install failed: {r.stdout[-1500:]} {r.stderr[-1500:]}"}
        r = runner.run([runner.python(), str(runner.inner / "capture_thread_check.py"),
                        str(runner.inner / "args.json")], "thread_check")
    finally:
        _keep(runner, f"thread-check-{n}")
        runner.close()
    line = next((x for x in r.stdout.splitlines() if x.startswith("GSIBL-CAPTURE-THREAD ")), None)
    if line is None:
        return {"error": f"no result (rc {r.returncode}): {r.stdout[-1500:]} {r.stderr[-2000:]}"}
    out = json.loads(line.split(" ", 1)[1])
    out["splats"] = n
    return out


# ------------------------------------------------------------------------------------------------------- output

def rows_of(results: dict) -> list[dict]:
    date = results["date"]
    rows = []
    for key, res in results["gui"].items():
        variant, n = key.split("-")
        stages = res.get("stages", {})
        failed_at = None
        for stage in GUI_STAGES:
            st = stages.get(stage)
            row = {"date": date, "device": DEVICE, "blender": "5.2 GUI (Xvfb)", "variant": variant, "splats": int(n),
                   "stage": stage, "wall_s": "", "max_block_s": "", "gaps_over_0_2": "", "fps": "",
                   "draw_ms_median": "", "new_images": "", "load1": "", "ok": False, "note": ""}
            if st is None or "wall_s" not in st:
                row["note"] = ("skipped: " + failed_at) if failed_at else (res.get("error") or "not run")[:300]
            else:
                row.update(wall_s=round(st["wall_s"], 3), max_block_s=round(st.get("max_gap_s", float("nan")), 3),
                           gaps_over_0_2=st.get("gaps_over_0_2", ""), load1=round(st["load_start"][0], 2),
                           ok=not st.get("timeout") and st.get("ok", True))
                if stage == "orbit" and "fps" in st:
                    # a draw that shows the region's last image again (a worker renders the new one, or the motion
                    # copy is still being built) has that image's render time: a changed render time is a new image
                    prev, new = stages.get("show", {}).get("first_render_ms"), 0
                    for _t, _s, ms, _d in st["frames_log"]:
                        new += ms != prev
                        prev = ms
                    row.update(fps=round(st["fps"], 3), draw_ms_median=round(st["draw_ms_median"], 1),
                               new_images=new,
                               note=f"{st['frames']} draws, {new} of them new images, scales {st['scales']}, "
                                    f"draw max {st['draw_ms_max']:.0f} ms")
                if stage == "show":
                    row["note"] = f"first draw {st.get('first_draw_ms', 0):.0f} ms"
                if stage in ("bake", "rebake", "rebake_hidden"):
                    rep = st.get("report") or "FAILED: empty report"
                    core = next((x for x in rep.splitlines() if x.startswith("render ")), rep.splitlines()[0])
                    row["note"] = (f"overlay draws during it: {st.get('overlay_draws', '?')} "
                                   f"({st.get('overlay_draw_s', float('nan')):.1f} s); CPU s main thread / process: "
                                   f"{st.get('main_thread_cpu_s', float('nan')):.1f} / "
                                   f"{st.get('process_cpu_s', float('nan')):.1f}; {core}")[:400]
                if stage == "import":
                    row["note"] = f"call returned after {st.get('call_returned_s', 0):.2f} s ({st.get('call')})"
                if st.get("timeout"):
                    row["note"] = f"stopped at the {results['stage_limit']:.0f} s limit"
                    failed_at = f"{stage} exceeded {results['stage_limit']:.0f} s"
            rows.append(row)
    for key, res in results["headless"].items():
        variant, n = key.split("-")
        for stage in HEADLESS_STAGES:
            st = res.get("rows", {}).get(stage)
            row = {"date": date, "device": DEVICE, "blender": "bpy 5.3 headless", "variant": variant,
                   "splats": int(n), "stage": stage, "wall_s": "", "max_block_s": "", "gaps_over_0_2": "", "fps": "",
                   "draw_ms_median": "", "new_images": "", "load1": "", "ok": False, "note": ""}
            if st is None:
                row["note"] = (res.get("error") or "not run")[-300:]
            else:
                core = next((x for x in st.get("result", "").splitlines() if x.startswith("render ")), "")
                row.update(wall_s=round(st["s"], 3), load1=round(st["load"][0], 2), ok=st["ok"],
                           note=core[:200] if st["ok"] else st["error"].strip().splitlines()[-1][:200])
            rows.append(row)
    return rows


def _cell(rows: list[dict], blender: str, variant: str, n: int, stage: str) -> dict | None:
    return next((r for r in rows if r["blender"] == blender and r["variant"] == variant and r["splats"] == n
                 and r["stage"] == stage), None)


def _fmt(x, digits: int = 1) -> str:
    return "–" if x in ("", None) else f"{x:.{digits}f}"


def table(results: dict, rows: list[dict]) -> str:
    sizes = results["sizes"]
    gui = "5.2 GUI (Xvfb)"
    head = ("| splats | stage | before: wall s | before: longest block s | before: gaps > 0.2 s | "
            "after: wall s | after: longest block s | after: gaps > 0.2 s | load (before / after) |\n"
            "|---|---|---|---|---|---|---|---|---|\n")
    lines = []
    for n in sizes:
        for stage in GUI_STAGES:
            cells = []
            loads = []
            for v in VARIANTS:
                r = _cell(rows, gui, v, n, stage)
                if r is None or r["wall_s"] == "":
                    cells += ["not run" if r is None else "skipped", "–", "–"]
                    loads.append("–")
                    continue
                wall = _fmt(r["wall_s"])
                if stage == "orbit" and r["fps"] != "":
                    wall = (f"{r['fps']:.2f} draws/s, {r['draw_ms_median']:.0f} ms/draw; {r['new_images']} new "
                            f"images in {r['wall_s']:.1f} s")
                if not r["ok"]:
                    wall += " (failed)" if stage != "orbit" else ""
                cells += [wall, _fmt(r["max_block_s"], 2), str(r["gaps_over_0_2"])]
                loads.append(_fmt(r["load1"], 1))
            lines.append(f"| {n / 1e6:g}M | {STAGE_TEXT[stage]} | " + " | ".join(cells) + f" | {' / '.join(loads)} |")
    gui_md = head + "\n".join(lines)

    hl = "bpy 5.3 headless"
    head2 = ("| splats | stage | before: s | after: s | load (before / after) |\n|---|---|---|---|---|\n")
    lines = []
    for n in sizes:
        for stage in HEADLESS_STAGES:
            cells, loads = [], []
            for v in VARIANTS:
                r = _cell(rows, hl, v, n, stage)
                if r is None or r["wall_s"] == "":
                    cells.append("not run")
                    loads.append("–")
                else:
                    cells.append(_fmt(r["wall_s"], 2) + ("" if r["ok"] else " (failed)"))
                    loads.append(_fmt(r["load1"], 1))
            lines.append(f"| {n / 1e6:g}M | {STAGE_TEXT[stage]} | " + " | ".join(cells) + f" | {' / '.join(loads)} |")
        ratios = []
        for v in VARIANTS:
            a, b = _cell(rows, hl, v, n, "import_native"), _cell(rows, hl, v, n, "peer_import")
            ok = a and b and a["wall_s"] != "" and b["wall_s"] != "" and a["ok"] and b["ok"]
            ratios.append(f"**{a['wall_s'] / b['wall_s']:.2f}×**" if ok else "–")
        lines.append(f"| {n / 1e6:g}M | our native import / Blender's importer | " + " | ".join(ratios) + " | |")
    return gui_md, head2 + "\n".join(lines)


def chart(results: dict, rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sizes = results["sizes"]
    fig, axes = plt.subplots(1, 3, figsize=(17, 5.2), gridspec_kw={"width_ratios": [4, 1.3, 3.2]})
    colours = {"before": "#c0504d", "after": "#4f81bd"}
    # 1: GUI wall (light) and longest main-thread block (dark) per stage and size
    ax = axes[0]
    stages = [s for s in GUI_STAGES if s != "orbit"]
    labels, x = [], 0.0
    for n in sizes:
        for stage in stages:
            for k, v in enumerate(VARIANTS):
                r = _cell(rows, "5.2 GUI (Xvfb)", v, n, stage)
                if r is None or r["wall_s"] == "":
                    ax.text(x + (k - 0.5) * 0.38, 0.3, "skipped", rotation=90, ha="center", fontsize=7)
                    continue
                ax.bar(x + (k - 0.5) * 0.38, r["wall_s"], 0.36, color=colours[v], alpha=0.35)
                ax.bar(x + (k - 0.5) * 0.38, r["max_block_s"], 0.36, color=colours[v])
            short = {"import": "import", "show": "Show\nSplats", "bake": "bake", "rebake": "re-bake",
                     "rebake_hidden": "re-bake,\noverlay off"}[stage]
            labels.append((x, f"{short}\n{n / 1e6:g}M"))
            x += 1.0
        x += 0.5
    ax.set_xticks([p for p, _ in labels], [t for _, t in labels], fontsize=7)
    ax.set_ylabel("seconds")
    ax.set_title("Blender 5.2 GUI: wall (light) and longest main-thread block (dark)", fontsize=10)
    from matplotlib.patches import Patch
    ax.legend(handles=[Patch(color=colours[v], label=v) for v in VARIANTS], fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    # 2: orbit frames per second
    ax = axes[1]
    for i, n in enumerate(sizes):
        for k, v in enumerate(VARIANTS):
            r = _cell(rows, "5.2 GUI (Xvfb)", v, n, "orbit")
            if r is not None and r["fps"] != "":
                ax.bar(i + (k - 0.5) * 0.38, r["new_images"] / r["wall_s"], 0.36, color=colours[v])
                ax.bar(i + (k - 0.5) * 0.38, r["fps"], 0.36, color=colours[v], alpha=0.3)
    ax.set_xticks(range(len(sizes)), [f"{n / 1e6:g}M" for n in sizes])
    ax.set_title("orbit: new images/s (dark), draws/s (light)", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    # 3: bpy 5.3 headless
    ax = axes[2]
    labels, x = [], 0.0
    for n in sizes:
        for stage in HEADLESS_STAGES:
            for k, v in enumerate(VARIANTS):
                r = _cell(rows, "bpy 5.3 headless", v, n, stage)
                if r is not None and r["wall_s"] != "":
                    ax.bar(x + (k - 0.5) * 0.38, r["wall_s"], 0.36, color=colours[v],
                           hatch="//" if stage == "peer_import" else None, edgecolor="white")
            labels.append((x, {"peer_import": "Blender's\nimporter", "import_native": "ours\nnative",
                               "import_mesh": "ours\nmesh", "bake": "bake", "rebake": "re-bake"}[stage]
                           + f"\n{n / 1e6:g}M"))
            x += 1.0
        x += 0.5
    ax.set_xticks([p for p, _ in labels], [t for _, t in labels], fontsize=7)
    ax.set_title("bpy 5.3 headless: seconds (hatched: Blender's own PLY importer)", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    fig.suptitle(f"Capture-sized scenes (issue 23), {results['date']}, {DEVICE}, load "
                 f"{results['load_range'][0]:.1f}–{results['load_range'][1]:.1f}", fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(results: dict, write: bool) -> str:
    rows = rows_of(results)
    loads = [r["load1"] for r in rows if r["load1"] != ""]
    results["load_range"] = (min(loads, default=0.0), max(loads, default=0.0))
    gui_md, hl_md = table(results, rows)
    z = results["zips"]
    dirty = (f" plus uncommitted changes of other work in {', '.join(z['after_dirty'])}" if z.get("after_dirty")
             else "")
    notes = []
    for key, res in results["gui"].items():
        if res.get("error"):
            notes.append(f"- GUI {key}: {res['error'][:300]}")
        for tb in res.get("tracebacks", [])[:1]:
            notes.append(f"- GUI {key}: a traceback in Blender's console: `{tb.strip().splitlines()[-1][:200]}`")
    for key, res in results["headless"].items():
        if res.get("error"):
            notes.append(f"- bpy 5.3 {key}: {res['error'].strip().splitlines()[-1][:300]}")
    thread_md = ""
    tc = results.get("thread_check")
    if tc and tc.get("runs"):
        lines = ["| how | wall s | process CPU s | load | the core's report |", "|---|---|---|---|---|"]
        for r in tc["runs"]:
            lines.append(f"| {r['how']} | {r['wall_s']:.2f} | {r['process_cpu_s']:.2f} | {r['load1']:.1f} | "
                         f"{r['core'].split(' (llvmpipe')[0]} |")
        import textwrap
        thread_md = ("\n".join(textwrap.wrap(
                     f"The same re-bake without any UI (bpy 5.3, the after zip, {tc['splats'] / 1e6:g}M splats as "
                     "Blender's splats, `benchmarks/trials/capture_thread_check.py`, `--thread-check`): inline "
                     "(`jobs.run_now`, what `execute()` and `blender -b` do) against a `jobs.Runner` worker ticked "
                     "every 0.1 s by a main thread that sleeps in between, alternating:", 116,
                     break_long_words=False, break_on_hyphens=False)) + "\n\n" + "\n".join(lines) + "\n\n")
    elif tc:
        thread_md = f"The thread check failed: {tc.get('error', '')[-300:]}\n\n"
    md = f"""{SECTION}

`.venv/bin/python benchmarks/capture_bench.py` ({results['date']}, {DEVICE}; load average
{results['load_range'][0]:.1f}–{results['load_range'][1]:.1f} over the rows — other engineers' work shared the
2 cores; whole run {results['total_s'] / 60:.0f} min). Scenes: `bench_scene` (SH degree 3, a 10 m box), stored
shuffled, binary PLY ({', '.join(f"{n / 1e6:g}M: {results['ply_mb'][str(n)]:.0f} MB" for n in results['sizes'])}).
**before**: the zip of commit {BEFORE_COMMIT} (before the jobs work); **after**: the zip of {z['after_commit']}{dirty}.
Each installed by Blender's installer into a fresh user directory. GUI: Blender {results.get('gui_blender', '5.2')}
under Xvfb, 3D View region {results.get('region', '?')}, overlay Resolution {results.get('resolution_scale', '?')};
the operators called as the UI calls them (import: EXEC_DEFAULT with `from_ui=True` where the operator has it, as the
file browser's Import button; bake: INVOKE_DEFAULT with the 3D View's window/area/region, as the panel's button),
jobs waited for by polling `blender.common.jobs.running()`. *Longest block*: the longest gap of a 50 ms heartbeat timer
during the stage (the main thread was away that long: the UI frozen); *gaps*: how many gaps exceeded 0.2 s. Show
Splats ends with the end of the overlay's first draw that rendered splats; orbit turns the view 2° every 0.1 s for 8
s (at least 3 frames) and counts the overlay's draws (`overlay.draw_log`): draws per second, the draw handler's
median time per draw, and how many draws showed a new image (a draw that shows the region's last image again while a
worker renders, or before the motion copy exists, repeats that image's render time). Bake: a probe at the box's
centre, face size 0 (auto), Lighting World Probe; re-bake: the probe moved 0.25 m, the button again; then once more
with Show Splats off (the probe moved back), to see what the overlay's redraws beside a job cost it. The load column
is the 1-minute load average at the start of each stage. The CSV's notes add, per bake, the overlay's draws during
it and the CPU seconds of Blender's main thread and of the whole process (`time.thread_time` / `time.process_time`
at the heartbeats), and the core's own render time from the bake report.

{gui_md}

bpy {results.get('bpy_version', '5.3')} headless, one process per zip and size (each import removed before the next;
the file read once into the page cache first). The ratio is our native import's time over Blender's own
`bpy.ops.wm.ply_import` of the same file in the same process.

{hl_md}

{thread_md}![capture-sized scenes, before against after](img/capture_bench.png)

CSV: `docs/bench/capture.csv`. Raw results and Blender's logs: `build/capture/`.
""" + ("\nProblems recorded in this run:\n\n" + "\n".join(notes) + "\n" if notes else "")
    print(md)
    if write:
        CSV_OUT.parent.mkdir(parents=True, exist_ok=True)
        with open(CSV_OUT, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        chart(results, rows, PNG_OUT)
        text = MD.read_text()
        if SECTION in text:
            start = text.index(SECTION)
            nxt = text.find("\n## ", start + len(SECTION))
            text = text[:start] + md.rstrip() + "\n" + (text[nxt:] if nxt >= 0 else "")
        else:
            text = text.rstrip() + "\n\n" + md
        MD.write_text(text)
        log(f"wrote {CSV_OUT}, {PNG_OUT}, {MD}")
    return md


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1000000,3000000")
    ap.add_argument("--quick", action="store_true", help="300k splats only, for trying it out")
    ap.add_argument("--parts", default="gui,headless")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--stage-limit", type=float, default=300.0, help="seconds a GUI stage may take")
    ap.add_argument("--keep-worktree", action="store_true")
    ap.add_argument("--no-write", action="store_true", help="print, leave docs/ alone")
    ap.add_argument("--tag", default="", help="results_<tag>.json instead of results.json (a repeat run)")
    ap.add_argument("--replot", metavar="RESULTS_JSON")
    ap.add_argument("--thread-check", metavar="RESULTS_JSON",
                    help="run benchmarks/trials/capture_thread_check.py (the after zip, bpy 5.3, the first size) and "
                         "add it to RESULTS_JSON and the outputs")
    a = ap.parse_args()
    if a.replot:
        write_outputs(json.loads(Path(a.replot).read_text()), not a.no_write)
        return
    sizes = [300_000] if a.quick else [int(s) for s in a.sizes.split(",")]
    if a.thread_check:
        import test_matrix as matrix
        matrix.TIMEOUT_S = 3600
        results = json.loads(Path(a.thread_check).read_text())
        zip_path = INPUTS / "after.zip"
        if not zip_path.exists():
            sys.exit(f"{zip_path} is missing: run the benchmark first")
        results["thread_check"] = run_thread_check(matrix, zip_path, sizes[0], 3)
        Path(a.thread_check).write_text(json.dumps(results, indent=1))
        write_outputs(results, not a.no_write)
        return
    parts, variants = a.parts.split(","), a.variants.split(",")
    import test_matrix as matrix
    matrix.TIMEOUT_S = 3600
    for root in ("sid", "trixie"):
        try:
            matrix.require_root(root)
        except BaseException as e:  # pytest's skip outside pytest
            sys.exit(f"the {root} root is not ready: {e}")
    t_start = time.perf_counter()
    WORK.mkdir(parents=True, exist_ok=True)
    results: dict = {"date": time.strftime("%Y-%m-%d"), "sizes": sizes, "stage_limit": a.stage_limit,
                     "gui": {}, "headless": {}, "ply_mb": {}}
    for n in sizes:
        results["ply_mb"][str(n)] = make_ply(n).stat().st_size / 1e6
    results["zips"] = {k: (str(v) if isinstance(v, Path) else v) for k, v in build_zips(a.keep_worktree).items()}
    log(f"zips: {results['zips']}")
    save = WORK / ("results_quick.json" if a.quick else f"results_{a.tag}.json" if a.tag else "results.json")
    results["variant_order"] = variants
    if a.tag:
        KEEP[0] = WORK / a.tag

    def checkpoint() -> None:
        results["total_s"] = time.perf_counter() - t_start
        save.write_text(json.dumps(results, indent=1))

    if "gui" in parts:
        for n in sizes:
            for v in variants:
                log(f"GUI {v} {n:,} (load {os.getloadavg()[0]:.2f})")
                res = run_gui(matrix, v, Path(results["zips"][v]), n, a.stage_limit)
                results["gui"][f"{v}-{n}"] = res
                info = res.get("info") or {}
                results.update(gui_blender=info.get("blender", results.get("gui_blender")),
                               region="×".join(map(str, info["region"])) if info.get("region") else
                               results.get("region"), resolution_scale=info.get("resolution_scale",
                                                                                 results.get("resolution_scale")))
                log(f"GUI {v} {n:,}: {res.get('error') or ''} " + ", ".join(
                    f"{k} {s.get('wall_s', float('nan')):.1f} s (block {s.get('max_gap_s', float('nan')):.1f})"
                    for k, s in res.get("stages", {}).items()) + f"; session {res.get('session_s', 0):.0f} s")
                checkpoint()
    if "headless" in parts:
        for n in sizes:
            for v in variants:
                log(f"bpy 5.3 {v} {n:,} (load {os.getloadavg()[0]:.2f})")
                res = run_headless(matrix, v, Path(results["zips"][v]), n)
                results["headless"][f"{v}-{n}"] = res
                results["bpy_version"] = (res.get("info") or {}).get("blender", results.get("bpy_version"))
                log(f"bpy 5.3 {v} {n:,}: {res.get('error') or ''} " + ", ".join(
                    f"{k} {s['s']:.1f} s{'' if s['ok'] else ' FAILED'}" for k, s in res.get("rows", {}).items())
                    + f"; session {res.get('session_s', 0):.0f} s")
                checkpoint()
    checkpoint()
    write_outputs(results, not a.no_write and not a.quick)


if __name__ == "__main__":
    main()
