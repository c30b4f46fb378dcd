"""Trials of a kernel, kept as patches against shaders/ (benchmarks/trials/*.patch), built and checked here and timed
on the GPU machine beside the committed kernels, in one process.

  python benchmarks/kernel_trials.py list
  python benchmarks/kernel_trials.py build [NAME ...] [--out out/trials]
  python benchmarks/kernel_trials.py check [NAME ...] [--out out/trials]
  python benchmarks/peer_bench.py bench --trials out/trials ...     (on the GPU machine: carry out/trials)

A patch's leading lines, before its first "--- ", say what the trial is, what it measured and the commit whose
shaders/ it applies to ("base:"); a line "ablation: yes" marks one meant to draw wrong images (a part of the kernel
switched off, to time the rest). build applies each patch to a copy of shaders/ and compiles, with
scripts/build_shaders.py's flags, every kernel whose SPIR-V then differs from the extension's, into
OUT/NAME/KERNEL.spv (the GPU machine has no glslc: build here and carry the folder). check renders
tests/test_raster_plane.py's cases and a mixed cube with each trial's kernels on this machine's device, each trial on
a Vulkan context of its own, and fails when a trial that is not an ablation moves any pixel more than the tests'
tolerance (or any depth more than 100 times it, in metres) from the committed kernels' images.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from bench_common import kernels_from  # noqa: E402

TRIALS = HERE / "trials"
TOL = 2e-4  # tests/test_renderer.py's image tolerance


def _build_shaders():
    spec = importlib.util.spec_from_file_location("build_shaders", ROOT / "scripts" / "build_shaders.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def header(patch: pathlib.Path) -> list[str]:
    """The patch's description: its lines before the diff."""
    lines = []
    for line in patch.read_text().splitlines():
        if line.startswith("--- "):
            break
        lines.append(line)
    return lines


def is_ablation(patch: pathlib.Path) -> bool:
    return any(line.strip().lower() == "ablation: yes" for line in header(patch))


def patches(names: list[str]) -> list[pathlib.Path]:
    found = sorted(TRIALS.glob("*.patch"))
    if not names:
        return found
    by_name = {p.stem: p for p in found}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise SystemExit(f"no trial {', '.join(missing)} in {TRIALS} (there: {', '.join(sorted(by_name))})")
    return [by_name[n] for n in names]


def build(patch: pathlib.Path, out: pathlib.Path) -> list[str]:
    """Builds one trial into out/NAME; returns the kernels it changes."""
    bs = _build_shaders()
    glslc = shutil.which("glslc")
    if glslc is None:
        raise SystemExit("glslc is missing: apt-get install glslc")
    dest = out / patch.stem
    shutil.rmtree(dest, ignore_errors=True)
    dest.mkdir(parents=True)
    with tempfile.TemporaryDirectory() as tmp:
        plain, trial = pathlib.Path(tmp) / "plain", pathlib.Path(tmp) / "trial"
        for root in (plain, trial):
            shutil.copytree(bs.SRC, root / "shaders")
        r = subprocess.run(["patch", "-p1", "-s", "--no-backup-if-mismatch", "-d", str(trial), "-i", str(patch)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit(f"{patch.name} does not apply to shaders/ as they are now:\n{r.stdout}{r.stderr}")
        changed = []
        for comp in sorted((trial / "shaders").glob("*.comp")):
            spv, base = dest / (comp.stem + ".spv"), plain / (comp.stem + ".spv")
            # against the unpatched sources built by this glslc: another glslc than the committed build's would
            # otherwise make every kernel a trial's, its compiler's changes mixed into the patch's
            err = bs.compile_comp(glslc, comp, spv, comp.parent) or bs.compile_comp(
                glslc, plain / "shaders" / comp.name, base, plain / "shaders")
            if err:
                raise SystemExit(f"{patch.name}: {comp.name} does not compile:\n{err}")
            if spv.read_bytes() == base.read_bytes():
                spv.unlink()
            else:
                changed.append(comp.stem)
                if base.read_bytes() != (bs.DST / spv.name).read_bytes():
                    print(f"warning: this glslc builds {comp.name} unpatched differently from the committed "
                          f"{spv.name}: time the trial against a build of the plain sources", file=sys.stderr)
    if not changed:
        raise SystemExit(f"{patch.name} changes no kernel")
    return changed


def _cases():
    """(name, scene, batch): the plain raster's cases of tests/test_raster_plane.py and a mixed 64² cube."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_raster_plane import CASES, _mixed

    from gs_ibl_addon.core.render.views import ViewBatch
    cases = [(name, make_scene(), make_batch()) for name, (make_scene, make_batch) in sorted(CASES.items())]
    return cases + [("cube64", _mixed(), ViewBatch.cubemap([0.05, -0.1, 0.02], 64))]


def _render(cases, folder: str | None):
    from gs_ibl_addon.core.render.renderer import SplatRenderer
    from gs_ibl_addon.core.vk.context import VulkanContext
    got = []
    with VulkanContext() as ctx, kernels_from(folder):
        for _, scene, batch in cases:
            r = SplatRenderer(scene, ctx)
            res = r.render(batch, depth=True)
            got.append((res.images, res.depths))
            r.close()
    return got


def check(selected: list[pathlib.Path], out: pathlib.Path) -> int:
    import numpy as np
    cases = _cases()
    base = _render(cases, None)
    bad = 0
    for patch in selected:
        folder = out / patch.stem
        if not folder.is_dir():
            raise SystemExit(f"{patch.stem} is not built: python benchmarks/kernel_trials.py build {patch.stem}")
        got = _render(cases, str(folder))
        worst, off = [], 0
        for (name, _, _), (bi, bd), (gi, gd) in zip(cases, base, got):
            di = max(float(np.abs(a - b).max()) for a, b in zip(bi, gi))
            dd = max(float(np.abs(a - b).max()) for a, b in zip(bd, gd))
            worst.append(f"{name} {di:.1e}/{dd:.1e}")
            ok = di <= TOL and dd <= TOL * 100  # depths in metres, the scenes' up to 50 m away
            off += not ok
        kind = "ablation, not judged" if is_ablation(patch) else "bit-equal" if all(
            w.endswith("0.0e+00/0.0e+00") for w in worst) else "within tolerance" if not off else "DIFFERS"
        bad += off and not is_ablation(patch)
        print(f"{patch.stem}: image/depth max |diff| " + ", ".join(worst) + f" ({kind})")
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["list", "build", "check"])
    ap.add_argument("names", nargs="*", help="trials (patch names without .patch); none: every one")
    ap.add_argument("--out", default=str(ROOT / "out" / "trials"))
    args = ap.parse_args()
    selected, out = patches(args.names), pathlib.Path(args.out)
    if args.mode == "list":
        for p in selected:
            print(f"{p.stem}:\n  " + "\n  ".join(header(p)))
        return 0
    if args.mode == "build":
        for p in selected:
            print(f"{p.stem}: {', '.join(build(p, out))} -> {os.path.relpath(out / p.stem)}")
        return 0
    return check(selected, out)


if __name__ == "__main__":
    sys.exit(main())
