"""The on-disk pipeline cache, cold against warm, in fresh processes (core/vk/pipeline_cache.py).

Each round runs, in new processes and in an order that alternates between rounds: the CLI's bake of samples/room.ply
and a child that makes every kernel's pipeline, once with an empty GS_IBL_CACHE_DIR folder (cold) and once with the
folder the cold run wrote (warm). ``--mesa`` does the same with Mesa's own shader disk cache (MESA_SHADER_CACHE_DIR)
cold and warm too, which is where lavapipe keeps its compiled code. Prints min / median per condition.

  python benchmarks/pipeline_cache_bench.py [--rounds 5] [--mesa]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_PIPELINES = """
import time
t0 = time.perf_counter()
from gs_ibl_addon.core.vk import KERNELS, VulkanContext
from gs_ibl_addon.core.vk.pipelines import get_pipeline
ctx = VulkanContext()
t1 = time.perf_counter()
for k in KERNELS.values():
    get_pipeline(ctx, k)
t2 = time.perf_counter()
pc = ctx.pipeline_cache
saves = []
for _ in range(20):  # what one write of the file costs: forced, the data unchanged
    pc._saved_size = None
    t = time.perf_counter(); pc.save(); saves.append(time.perf_counter() - t)
size = pc.path.stat().st_size if pc.path else 0
print(t2 - t1, sorted(saves)[10], size, pc.loaded_bytes, len(KERNELS))
ctx.close()
"""


def _run(args: list[str], env: dict) -> tuple[float, str]:
    t = time.perf_counter()
    r = subprocess.run(args, env=env, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if r.returncode:
        raise SystemExit(r.stderr)
    return wall, r.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--mesa", action="store_true", help="also vary Mesa's shader disk cache (cold / warm)")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="gs-ibl-pc-bench-")
    out = os.path.join(tmp, "bake")
    mesa_states = ("mesa-warm", "mesa-cold") if a.mesa else ("mesa-as-is",)
    times: dict[tuple, list[float]] = {}
    info = {}
    try:
        for rnd in range(a.rounds):
            for what in ("bake", "pipelines"):
                for mesa in (mesa_states if rnd % 2 == 0 else mesa_states[::-1]):
                    ours = os.path.join(tmp, f"ours-{what}-{mesa}")
                    env = dict(os.environ, GS_IBL_CACHE_DIR=ours, PYTHONPATH=ROOT)
                    if mesa == "mesa-cold":
                        env["MESA_SHADER_CACHE_DISABLE"] = "true"
                    elif mesa == "mesa-warm":
                        env["MESA_SHADER_CACHE_DIR"] = os.path.join(tmp, "mesa")  # filled by the first run
                    cmd = ([sys.executable, "-m", "gs_ibl_addon", "bake", "samples/room.ply", "--out", out]
                           if what == "bake" else [sys.executable, "-c", _PIPELINES])
                    # cold then warm on even rounds, warm (from the previous round's folder) then cold on odd ones
                    order = ("cold", "warm") if rnd % 2 == 0 else ("warm", "cold")
                    for state in order:
                        if state == "cold":
                            shutil.rmtree(ours, ignore_errors=True)
                        elif not os.path.isdir(ours):
                            _run(cmd, env)  # fill it first
                        wall, stdout = _run(cmd, env)
                        if what == "pipelines":
                            create, save, size, loaded, n = stdout.split()
                            times.setdefault((what + " (create all)", mesa, state), []).append(float(create))
                            times.setdefault(("one file write", mesa, state), []).append(float(save))
                            info[(mesa, state)] = f"file {size} B, loaded {loaded} B, {n} pipelines"
                        times.setdefault((what + " (process wall)", mesa, state), []).append(wall)
        for key, ts in sorted(times.items()):
            print(f"{' / '.join(key):48s} n={len(ts)}  min {min(ts) * 1e3:8.1f} ms  median "
                  f"{statistics.median(ts) * 1e3:8.1f} ms")
        for key, s in sorted(info.items()):
            print(" / ".join(key), s)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
