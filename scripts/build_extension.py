#!/usr/bin/env python3
"""Build the Blender extension zip (gs_ibl-<version>.zip) from this repository.

The zip's root must hold blender_manifest.toml next to __init__.py, so the package is staged first:
    <stage>/  = contents of gs_ibl_addon/  +  the repo's top-level blender_manifest.toml  +  wheels/
and then zipped by, in order of preference:
    1. a Blender binary:  blender --command extension build        (--blender PATH or `blender` on PATH)
    2. the same builder shipped inside the bpy module (bl_pkg/cli/blender_ext.py), run with this Python
    3. a plain zipfile writer that honours the manifest's [build] paths_exclude_pattern
Wheels named in the manifest are taken from a cache folder (default build/wheel-cache, or GS_IBL_WHEEL_CACHE);
only a wheel missing there is fetched, with `pip download` for that wheel's exact Python/platform tags, so a second
build downloads nothing. A compiled package (cffi) ships as one wheel per platform tagged py3-none that holds the
extension module of every Python Blender runs on (FAT_WHEELS): Blender 4.2.0 ignores a wheel's Python tag and
installs the lexicographically last of several (cp314 on a cp311 Blender), so one wheel per platform is the only
layout every Blender installs right. The default output is one zip for every platform (Blender installs only the wheels
for its
own platform and Python); --split-platforms makes one zip per platform instead (for extensions.blender.org).
Compiled shaders (gs_ibl_addon/shaders/*.spv) travel with the package; the GLSL in the repo's shaders/ does not.
"""
from __future__ import annotations

import argparse
import fnmatch
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "gs_ibl_addon"
MANIFEST = ROOT / "blender_manifest.toml"


def read_manifest(path: Path = MANIFEST) -> dict:
    with open(path, "rb") as f:
        return tomllib.load(f)


# ---------------------------------------------------------------------------------------------- wheels

def _wheel_tags(filename: str) -> tuple[str, str, str, str, list[str]]:
    """name, version, python tag, abi tag, platform tags of a wheel file name (PEP 427)."""
    parts = filename[:-len(".whl")].split("-")
    if len(parts) < 5:
        raise SystemExit(f"{filename}: not a wheel file name (name-version-python-abi-platform.whl)")
    name, version, py, abi, plat = parts[0], parts[1], parts[-3], parts[-2], parts[-1]
    return name, version, py, abi, plat.split(".")


# wheel platform tag (its machine part) -> Blender's platform names; the OS part is matched by prefix below.
_MACHINES = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64", "arm64": "arm64"}
_SYSTEMS = (("manylinux", "linux"), ("musllinux", "linux"), ("linux", "linux"), ("macosx", "macos"), ("win", "windows"))


def blender_platforms(filename: str) -> set[str]:
    """Blender platforms ("linux-x64", "macos-arm64", ...) a wheel file serves; {"any"} for a pure-Python wheel.

    Same answer as Blender's own blender_platforms_from_wheel_platform (a test compares them).
    """
    out: set[str] = set()
    for tag in _wheel_tags(filename)[4]:
        if tag == "any":
            out.add("any")
            continue
        system = next((b for w, b in _SYSTEMS if tag.startswith(w)), None)
        if system is None:
            raise SystemExit(f"{filename}: unknown wheel platform tag {tag!r}")
        if system == "macos" and tag.endswith("_universal2"):
            out |= {"macos-x64", "macos-arm64"}
            continue
        machine = next((b for w, b in _MACHINES.items() if tag.endswith("_" + w)), tag.rpartition("_")[2])
        out.add(f"{system}-{machine}")
    return out


def check_wheels(manifest: dict) -> None:
    """Each compiled wheel serves a declared platform, and each declared platform gets every compiled package."""
    platforms = set(manifest.get("platforms", []))
    served: dict[str, set[str]] = {}
    for rel in manifest.get("wheels", []):
        name = Path(rel).name
        plats = blender_platforms(name) - {"any"}
        if plats and platforms and not plats & platforms:
            raise SystemExit(f"{MANIFEST.name}: {name} is for {sorted(plats)}, none of platforms = {sorted(platforms)}")
        if plats:
            served.setdefault(_wheel_tags(name)[0], set()).update(plats)
    for package, plats in served.items():
        if platforms - plats:
            raise SystemExit(f"{MANIFEST.name}: no {package} wheel for {sorted(platforms - plats)}: add one to "
                             "wheels or drop the platform")


# package -> the Python tags whose compiled modules its py3-none-<platform> wheel carries side by side
FAT_WHEELS = {"cffi": ("cp311", "cp313", "cp314")}


def fat_wheel_parts(filename: str) -> list[str]:
    """The per-Python wheels a fat wheel (FAT_WHEELS) is merged from; [] for any other wheel."""
    name, version, py, abi, plats = _wheel_tags(filename)
    if name not in FAT_WHEELS or (py, abi) != ("py3", "none"):
        return []
    return [f"{name}-{version}-{t}-{t}-{'.'.join(plats)}.whl" for t in FAT_WHEELS[name]]


def _record_line(path: str, data: bytes) -> str:
    import base64
    import hashlib
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{path},sha256={digest},{len(data)}"


def merge_wheels(parts: list[Path], target: Path) -> None:
    """One wheel holding every file of ``parts`` (wheels of one package and version for several Pythons): the pure
    files, which must be identical in all, once, and each part's own compiled module. Written reproducibly (fixed
    times, sorted entries) with its WHEEL tags set to py3-none-<platform> and a fresh RECORD."""
    files: dict[str, bytes] = {}
    dist_info = None
    for part in parts:
        with zipfile.ZipFile(part) as z:
            for n in z.namelist():
                if n.endswith("/"):
                    continue
                if ".dist-info/" in n:
                    dist_info = n.split("/")[0]
                    if n.endswith(("/RECORD", "/WHEEL")):
                        continue
                data = z.read(n)
                if n in files and files[n] != data:
                    raise SystemExit(f"{part.name}: {n} differs from the other Pythons' copy: cannot merge")
                files[n] = data
    plats = _wheel_tags(target.name)[4]
    wheel = "Wheel-Version: 1.0\nGenerator: gs-ibl build_extension.py\nRoot-Is-Purelib: false\n" + \
        "".join(f"Tag: py3-none-{p}\n" for p in plats)
    files[f"{dist_info}/WHEEL"] = wheel.encode()
    record = [_record_line(n, d) for n, d in sorted(files.items())] + [f"{dist_info}/RECORD,,"]
    files[f"{dist_info}/RECORD"] = ("\n".join(record) + "\n").encode()
    tmp = target.with_suffix(".part")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for n in sorted(files):
            info = zipfile.ZipInfo(n, date_time=(2020, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            z.writestr(info, files[n])
    tmp.replace(target)


def fetch_wheel(filename: str, cache: Path) -> Path:
    """The wheel from the cache, downloaded first (exactly that file's tags) if it is not there; a fat wheel is
    merged from its per-Python wheels."""
    target = cache / filename
    if target.is_file():
        return target
    parts = fat_wheel_parts(filename)
    if parts:
        merge_wheels([fetch_wheel(p, cache) for p in parts], target)
        return target
    cache.mkdir(parents=True, exist_ok=True)
    name, version, py, abi, plats = _wheel_tags(filename)
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "-d", str(cache),
           f"{name}=={version}"]
    if py.startswith("cp") and py[2:].isdigit():
        cmd += ["--implementation", "cp", "--python-version", py[2] + "." + py[3:], "--abi", abi]
    for p in plats:
        if p != "any":
            cmd += ["--platform", p]
    print("[build] fetching", filename)
    subprocess.run(cmd, check=True)
    if not target.is_file():
        raise SystemExit(f"pip downloaded {name} {version} but not {filename}: fix the wheel name in {MANIFEST.name}")
    return target


# ---------------------------------------------------------------------------------------------- staging

def _ignore_build_junk(_dir: str, names: list[str]) -> set[str]:
    return {n for n in names if n == "__pycache__" or n.endswith(".pyc")}


def stage(stage_dir: Path, cache: Path, manifest: dict) -> None:
    """Lay out the zip's root: package contents, the manifest beside __init__.py, and wheels/."""
    if stage_dir.exists():
        shutil.rmtree(stage_dir)
    shutil.copytree(PACKAGE, stage_dir, ignore=_ignore_build_junk)
    shutil.copy2(MANIFEST, stage_dir / "blender_manifest.toml")
    check_wheels(manifest)
    for rel in manifest.get("wheels", []):
        rel_path = Path(rel)
        src = fetch_wheel(rel_path.name, cache)
        dst = stage_dir / rel_path
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dst)
    if not list((stage_dir / "shaders").glob("*.spv")):
        print("[build] warning: no compiled shaders in gs_ibl_addon/shaders/ (run scripts/build_shaders.py); "
              "the extension will not be able to render", file=sys.stderr)


# ---------------------------------------------------------------------------------------------- zipping

def excluded(rel: str, is_dir: bool, patterns: list[str]) -> bool:
    """gitignore-style test for the patterns the manifest uses ('name/', '/anchored', '*.ext', '.*').

    Used only when no Blender builder is around; tests compare it with Blender's own matcher.
    """
    parts = rel.split("/")
    for pat in patterns:
        dir_only = pat.endswith("/")
        p = pat.rstrip("/")
        if p.startswith("/") or "/" in p:  # anchored at the package root
            p = p.lstrip("/")
            n = p.count("/") + 1
            if len(parts) >= n and fnmatch.fnmatchcase("/".join(parts[:n]), p):
                # a match on the whole path must respect dir_only; a match on a prefix is a parent folder
                if len(parts) > n or not dir_only or is_dir:
                    return True
        else:
            for i, comp in enumerate(parts):
                last = i == len(parts) - 1
                if fnmatch.fnmatchcase(comp, p) and (not last or not dir_only or is_dir):
                    return True
    return False


def zip_plain(stage_dir: Path, out: Path, manifest: dict) -> None:
    patterns = manifest.get("build", {}).get("paths_exclude_pattern", [])
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for dirpath, dirnames, filenames in os.walk(stage_dir):
            rel_dir = Path(dirpath).relative_to(stage_dir).as_posix()
            rel_dir = "" if rel_dir == "." else rel_dir + "/"
            dirnames[:] = sorted(d for d in dirnames if not excluded(rel_dir + d, True, patterns))
            for f in sorted(filenames):
                rel = rel_dir + f
                if f != "blender_manifest.toml" and excluded(rel, False, patterns):
                    continue
                z.write(Path(dirpath) / f, rel)


def bpy_builder() -> Path | None:
    """Blender's extension builder as shipped inside the bpy module, if bpy is installed (without importing it)."""
    import importlib.util
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    for loc in spec.submodule_search_locations:
        for cand in Path(loc).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"):
            return cand
    return None


def build(out: Path, cache: Path, method: str = "auto", blender: str | None = None,
          split_platforms: bool = False) -> tuple[Path, str]:
    """Build the zip ``out``; with ``split_platforms``, one zip per declared platform instead, named
    ``<out stem>-<platform>.zip`` beside ``out`` (Blender's own naming; list them with split_outputs)."""
    manifest = read_manifest()
    build_dir = ROOT / "build" / "extension"
    stage_dir = build_dir / "stage"
    stage(stage_dir, cache, manifest)
    out.parent.mkdir(parents=True, exist_ok=True)
    for old in [out] + split_outputs(out, manifest):
        if old.exists():
            old.unlink()
    split = ["--split-platforms"] if split_platforms else []
    blender = blender or shutil.which("blender")
    if method in ("auto", "blender") and blender:
        subprocess.run([blender, "--factory-startup", "--command", "extension", "build", "--source-dir", str(stage_dir),
                        "--output-filepath", str(out), *split], check=True)
        return out, "blender"
    if method == "blender":
        raise SystemExit("no Blender binary: pass --blender PATH or put `blender` on PATH")
    builder = bpy_builder() if method in ("auto", "bpy") else None
    if builder is not None:
        subprocess.run([sys.executable, str(builder), "build", "--source-dir", str(stage_dir),
                        "--output-filepath", str(out), *split], check=True)
        return out, "bpy"
    if method == "bpy":
        raise SystemExit("the bpy module is not installed in this Python")
    if split_platforms:
        # Blender's builder also rewrites each zip's manifest ([build.generated]); not worth re-implementing.
        raise SystemExit("--split-platforms needs Blender's builder: a Blender binary or the bpy module")
    zip_plain(stage_dir, out, manifest)
    return out, "zipfile"


def split_outputs(out: Path, manifest: dict | None = None) -> list[Path]:
    """The per-platform zips a split build of ``out`` writes (gs_ibl.zip -> gs_ibl-linux_x64.zip, ...)."""
    manifest = manifest or read_manifest()
    return [out.with_name(f"{out.stem}-{p.replace('-', '_')}{out.suffix}") for p in manifest.get("platforms", [])]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--output", type=Path, help="zip path (default build/gs_ibl-<version>.zip)")
    ap.add_argument("--wheel-cache", type=Path,
                    default=Path(os.environ.get("GS_IBL_WHEEL_CACHE", ROOT / "build" / "wheel-cache")))
    ap.add_argument("--method", choices=("auto", "blender", "bpy", "zipfile"), default="auto")
    ap.add_argument("--blender", help="path of a Blender binary to build with")
    ap.add_argument("--split-platforms", action="store_true",
                    help="one zip per platform (for extensions.blender.org) instead of one zip for all")
    ap.add_argument("--no-shaders", action="store_true", help="do not run scripts/build_shaders.py first")
    args = ap.parse_args(argv)
    if not args.no_shaders and (ROOT / "scripts" / "build_shaders.py").is_file():
        subprocess.run([sys.executable, str(ROOT / "scripts" / "build_shaders.py")], check=True)
    manifest = read_manifest()
    out = args.output or ROOT / "build" / f"{manifest['id']}-{manifest['version']}.zip"
    path, how = build(out.resolve(), args.wheel_cache.resolve(), args.method, args.blender, args.split_platforms)
    for p in split_outputs(path, manifest) if args.split_platforms else [path]:
        print(f"[build] {p} ({how}, {p.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
