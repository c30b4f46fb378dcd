"""Native Splats (issue 36 item 1) in a real Blender 5.3 (the bpy 5.3 root, the built zip installed by Blender's
installer): the guitar imported by our importer as a native Gaussian-splat Point Cloud, F12 in Cycles and in EEVEE
with each choice, through benchmarks/native_frame_bench.py's in-Blender half (the renders its benchmark times).

Each choice renders the splats once: with Blender, Blender's engine draws them and we draw nothing; with GS-IBL,
we draw them and the frame is exactly our FRONT layer (Blender drew none of them: its render alone is empty), and
the user's object keeps its camera icon. Both cover about the same part of the frame.

Skipped unless the trixie root is made (`scripts/blender_roots.sh ensure trixie`; scripts/test_real_blender.sh).
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import test_matrix as matrix  # noqa: E402 (the matrix's runner, installer and roots)

REPO = matrix.REPO
ENTRY = next(e for e in matrix.ENTRIES if e.name == "bpy-5.3")
BENCH = REPO / "benchmarks" / "native_frame_bench.py"
SIZE = (96, 54)
# the frame's mean alpha, Blender's against ours: EEVEE's stochastic splats at 2 samples and a 96x54 frame's outline
# (measured 0.282 against 0.316); splats missing is 100% (a second drawing is caught by the render-equals-FRONT check)
COVERAGE_RTOL = 0.2


def test_each_choice_renders_the_splats_once(tmp_path):
    matrix.require_root(ENTRY.root)
    sys.path.insert(0, str(REPO / "benchmarks"))
    import fidelity_bench as fb
    name, path, up = fb.parse_capture("guitar")
    cv = fb.camera_views(fb.load_capture(path), up, *SIZE)[0]
    runner = matrix.Runner(ENTRY, tmp_path)
    try:
        zip_path = matrix.built_zip()
        shutil.copy(zip_path, runner.host / "gs_ibl.zip")
        for f in (BENCH, HERE / "blender_scene.py", Path(path)):
            shutil.copy(f, runner.host / f.name)
        methods = [{"name": f"{engine}-{choice}", "engine": engine, "choice": choice, "samples": 2,
                    "denoise": False, "sizes": [list(SIZE)]}
                   for engine in ("cycles", "eevee") for choice in ("BLENDER", "GSIBL")]
        camera = [*cv.matrix.ravel(), cv.tan_x, cv.tan_y, *cv.shift]
        job = {"work": str(runner.inner), "threads": 2, "near": 0.1, "far": 1000.0, "size": list(SIZE),
               "captures": [{"name": name, "path": str(runner.inner / Path(path).name),
                             "views": [{"name": cv.name, "camera": camera}]}], "methods": methods}
        (runner.host / "args.json").write_text(json.dumps(job))
        assert matrix._install(runner, str(runner.inner / "gs_ibl.zip")).returncode == 0, \
            (runner.host / "install.log").read_text()[-2000:]
        r = runner.run([runner.python(), str(runner.inner / BENCH.name), "in-blender",
                        str(runner.inner / "args.json")], "native_choice")
        tag = "GSIBL-NATIVE-FRAME "
        line = next((x for x in r.stdout.splitlines() if x.startswith(tag)), None)
        assert line, f"no result (rc {r.returncode}): {r.stdout[-2000:]}\n{r.stderr[-3000:]}"
        rows = {row["method"]: row for row in json.loads(line[len(tag):])["rows"]}
        images = {p.stem.split("_")[-1]: np.load(p).astype(np.float32) for p in runner.host.glob("*.npy")}
    finally:
        runner.close()
    for engine in ("cycles", "eevee"):
        blender, ours = rows[f"{engine}-BLENDER"], rows[f"{engine}-GSIBL"]
        assert not blender["ours_drew"] and blender["coverage"] > 0.1, blender  # Blender drew them, we did not
        assert ours["ours_drew"] and ours["render_minus_front"] != "" and ours["render_minus_front"] < 1e-4, ours
        assert ours["camera_icon_after"] and blender["camera_icon_after"]
        assert not ours["messages"], ours["messages"]
        a, b = images[f"{engine}-BLENDER"], images[f"{engine}-GSIBL"]
        assert abs(a[..., 3].mean() - b[..., 3].mean()) < COVERAGE_RTOL * b[..., 3].mean(), \
            (engine, a[..., 3].mean(), b[..., 3].mean())
