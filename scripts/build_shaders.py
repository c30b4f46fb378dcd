"""Compile shaders/*.comp (GLSL 450) to gs_ibl_addon/shaders/*.spv, only where a source or include is newer.

The SPIR-V is committed, so an installed extension and a machine without glslc still work.
"""
from __future__ import annotations

import pathlib
import shutil
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT / "shaders"
DST = ROOT / "gs_ibl_addon" / "shaders"


def main() -> int:
    glslc = shutil.which("glslc")
    DST.mkdir(parents=True, exist_ok=True)
    includes = max((p.stat().st_mtime for p in SRC.glob("*.glsl")), default=0.0)
    built = 0
    for comp in sorted(SRC.glob("*.comp")):
        out = DST / (comp.stem + ".spv")
        if out.exists() and out.stat().st_mtime >= max(comp.stat().st_mtime, includes):
            continue
        if glslc is None:
            if out.exists():
                continue
            print(f"glslc is missing and {out} is not built: apt-get install glslc", file=sys.stderr)
            return 1
        cmd = [glslc, "--target-env=vulkan1.2", "-O", "-I", str(SRC), str(comp), "-o", str(out)]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            print(r.stderr, file=sys.stderr)
            return r.returncode
        built += 1
    if built:
        print(f"[shaders] compiled {built} shader(s) into {DST.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
