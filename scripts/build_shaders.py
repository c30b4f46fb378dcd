"""Compile shaders/*.comp (GLSL 450) to gs_ibl_addon/shaders/*.spv where a source or an include changed.

First shaders/constants.glsl is written from gs_ibl_addon/core/vk/constants.py (the numbers Python and GLSL share),
so the two cannot drift; tests/test_kernels.py checks it is current and that every kernel's bindings, push
constants and local size in the SPIR-V match gs_ibl_addon/core/vk/kernels.py.

The SPIR-V is committed, so an installed extension and a machine without glslc still work. What each .spv was
built from is recorded as a hash (gs_ibl_addon/shaders/sources.json), not judged by file times: a fresh clone
gives every file the same time, and another glslc version would otherwise rewrite committed files for nothing.
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import pathlib
import shutil
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT / "shaders"
DST = ROOT / "gs_ibl_addon" / "shaders"
RECORD = DST / "sources.json"
CONSTANTS_PY = ROOT / "gs_ibl_addon" / "core" / "vk" / "constants.py"
CONSTANTS_GLSL = SRC / "constants.glsl"
# No -O (spirv-opt): NVIDIA's compiler did better with glslc's plain SPIR-V. H200, 2026-12-04 (docs/benchmarks.md):
# the plain raster held 61 registers with -O and 53 without, and rastered 6M splats at 1024² in 10.1 -> 8.9 ms
# (shell), 3.5 -> 3.2 (random); the radix scatter 71 -> 68 registers; no stage got slower. Lavapipe optimises the
# SPIR-V itself with LLVM.
GLSLC_FLAGS = ("--target-env=vulkan1.2",)


def constants_glsl() -> str:
    """shaders/constants.glsl as constants.py says it should read (loaded by path: no package imports)."""
    spec = importlib.util.spec_from_file_location("gs_ibl_constants", CONSTANTS_PY)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.glsl_source()


def source_hash(comp: pathlib.Path) -> str:
    h = hashlib.sha1(comp.read_bytes())
    h.update(" ".join(GLSLC_FLAGS).encode())  # other flags: another build
    for inc in sorted(SRC.glob("*.glsl")):  # includes: any change rebuilds every shader (they are few and small)
        h.update(inc.name.encode())
        h.update(inc.read_bytes())
    return h.hexdigest()


def compile_comp(glslc: str, comp: pathlib.Path, out: pathlib.Path, include: pathlib.Path = SRC) -> str:
    """Builds one kernel as the extension's are built (benchmarks/kernel_trials.py builds its trials so); returns
    glslc's errors, empty when it succeeded."""
    r = subprocess.run([glslc, *GLSLC_FLAGS, "-I", str(include), str(comp), "-o", str(out)], capture_output=True,
                       text=True)
    return r.stderr if r.returncode != 0 else ""


def main() -> int:
    text = constants_glsl()
    if not CONSTANTS_GLSL.exists() or CONSTANTS_GLSL.read_text() != text:
        CONSTANTS_GLSL.write_text(text)
        print(f"[shaders] wrote {CONSTANTS_GLSL.relative_to(ROOT)}")
    glslc = shutil.which("glslc")
    DST.mkdir(parents=True, exist_ok=True)
    record = json.loads(RECORD.read_text()) if RECORD.exists() else {}
    built = 0
    for comp in sorted(SRC.glob("*.comp")):
        out = DST / (comp.stem + ".spv")
        digest = source_hash(comp)
        if out.exists() and record.get(comp.name) == digest:
            continue
        if glslc is None:
            print(f"glslc is missing and {out.name} is not built from the current {comp.name}: apt-get install glslc",
                  file=sys.stderr)
            return 1
        err = compile_comp(glslc, comp, out)
        if err:
            print(err, file=sys.stderr)
            return 1
        record[comp.name] = digest
        built += 1
    if built:
        RECORD.write_text(json.dumps(dict(sorted(record.items())), indent=1) + "\n")
        print(f"[shaders] compiled {built} shader(s) into {DST.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
