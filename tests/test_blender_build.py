"""The extension zip: layout Blender needs, wheels bundled, exclusions, and Blender's own validator."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
import build_extension as be  # noqa: E402

CACHE = os.path.join(ROOT, "build", "wheel-cache")  # shared with scripts/build_extension.py: fetched once


def _check_layout(path):
    manifest = be.read_manifest()
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
    assert "blender_manifest.toml" in names and "__init__.py" in names  # side by side at the zip's root
    assert "blender/registration.py" in names and "core/scene.py" in names
    for w in manifest["wheels"]:
        assert w.removeprefix("./") in names, w
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
    assert not [n for n in names if n.startswith("gs_ibl_addon/") or n.endswith((".comp", ".glsl"))]
    spv = {os.path.basename(p) for p in os.listdir(os.path.join(ROOT, "gs_ibl_addon", "shaders"))
           if p.endswith(".spv")} if os.path.isdir(os.path.join(ROOT, "gs_ibl_addon", "shaders")) else set()
    assert {f"shaders/{s}" for s in spv} <= names
    return names


def test_manifest_names_no_website_that_does_not_exist():
    # Blender shows `website` as the extension's Website button; it led to a repository that does not exist (issue
    # 35). The field is optional: none until the project has a page.
    assert "website" not in be.read_manifest()


@pytest.mark.parametrize("method", ["bpy", "zipfile"])
def test_build_zip(tmp_path, method):
    if method == "bpy" and be.bpy_builder() is None:
        pytest.skip("bpy module not installed")
    out, how = be.build(tmp_path / "gs_ibl.zip", __import__("pathlib").Path(CACHE), method)
    assert how == method
    _check_layout(out)


def test_both_builders_ship_the_same_files(tmp_path):
    if be.bpy_builder() is None:
        pytest.skip("bpy module not installed")
    from pathlib import Path
    a, _ = be.build(tmp_path / "a.zip", Path(CACHE), "bpy")
    b, _ = be.build(tmp_path / "b.zip", Path(CACHE), "zipfile")
    with zipfile.ZipFile(a) as za, zipfile.ZipFile(b) as zb:
        assert set(za.namelist()) == set(zb.namelist())


def _blender_ext():
    """Blender's extension builder module (bl_pkg/cli/blender_ext.py) from the bpy module."""
    builder = be.bpy_builder()
    if builder is None:
        pytest.skip("bpy module not installed")
    if "blender_ext" not in sys.modules:
        spec = importlib.util.spec_from_file_location("blender_ext", builder)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["blender_ext"] = mod
        spec.loader.exec_module(mod)
    return sys.modules["blender_ext"]


def test_exclude_matcher_agrees_with_blenders():
    mod = _blender_ext()
    patterns = be.read_manifest()["build"]["paths_exclude_pattern"] + ["/shaders/*.comp", "docs/"]
    matcher = mod.PathPatternMatch(patterns)
    paths = ["__init__.py", "__pycache__/", "core/__pycache__/", "core/__pycache__/x.pyc", "core/scene.py", "x.pyc",
             ".hidden", "core/.git/", "tests/", "core/tests/", "tests/a.py", "shaders/a.spv", "shaders/a.comp",
             "core/shaders/a.comp", "docs/", "core/docs/", "docs", "wheels/a.whl"]
    for p in paths:
        is_dir = p.endswith("/")
        assert be.excluded(p.rstrip("/"), is_dir, patterns) == matcher.test_path(p), p


# The Pythons Blender runs on: 3.11 in 4.2-5.0, 3.13 from 5.1 (official builds), 3.14 (Linux distributions' builds,
# e.g. Debian sid's 5.2). Each platform's one cffi wheel carries all three.
PYTHONS = {"cp311", "cp313", "cp314"}
_BACKEND_PY = {"cpython-311": "cp311", "cpython-313": "cp313", "cpython-314": "cp314",
               "cp311": "cp311", "cp313": "cp313", "cp314": "cp314"}  # Linux/macOS and Windows module suffixes


def _cffi_contents(z: zipfile.ZipFile) -> dict[str, list[str]]:
    """Blender platform -> python tags of the _cffi_backend modules in that platform's cffi wheel(s), one entry per
    wheel and module (a duplicate wheel or module shows twice)."""
    import io
    out: dict[str, list[str]] = {}
    for n in z.namelist():
        if not n.startswith("wheels/cffi-"):
            continue
        with zipfile.ZipFile(io.BytesIO(z.read(n))) as w:
            tags = sorted(_BACKEND_PY[m.split(".")[1].rsplit("-", 1)[0] if m.endswith(".pyd") else
                                      "-".join(m.split(".")[1].split("-")[:2])]
                          for m in w.namelist() if m.startswith("_cffi_backend."))
        for p in be.blender_platforms(os.path.basename(n)):
            out.setdefault(p, []).extend(tags)
    return out


def test_zip_has_one_cffi_wheel_per_platform_with_every_python(tmp_path):
    """Every declared platform gets one cffi wheel holding _cffi_backend for each Blender Python (4.2.0 installs
    the last of several wheels whatever its Python tag), and nothing else is compiled."""
    manifest = be.read_manifest()
    platforms = manifest["platforms"]
    assert {"linux-x64", "windows-x64", "macos-arm64", "macos-x64"} <= set(platforms)
    out, how = be.build(tmp_path / "gs_ibl.zip", Path(CACHE), "auto")
    with zipfile.ZipFile(out) as z:
        names = z.namelist()
        contents = _cffi_contents(z)
    assert contents == {p: sorted(PYTHONS) for p in platforms}
    cffi_wheels = [n for n in names if n.startswith("wheels/cffi-")]
    assert len(cffi_wheels) == len(platforms) and all("-py3-none-" in n for n in cffi_wheels)
    compiled = [n for n in names if n.startswith("wheels/") and not n.endswith("-none-any.whl")]
    assert all(n.startswith("wheels/cffi-") for n in compiled), compiled
    size = out.stat().st_size
    print(f"\n[zip] {out.name} ({how}): {size / 1e6:.2f} MB, {len(cffi_wheels)} cffi wheels for {len(platforms)} "
          "platforms")
    assert size < 5e6  # one zip for all platforms stays small (measured 2.9 MB)


def test_fat_wheel_is_a_valid_wheel(tmp_path):
    """The merged wheel's RECORD lists every file with its hash and size, and its pure files are cffi's own."""
    import base64
    import hashlib
    name = next(os.path.basename(w) for w in be.read_manifest()["wheels"] if "cffi" in w and "x86_64.many" in w)
    parts = be.fat_wheel_parts(name)
    assert len(parts) == len(PYTHONS)
    fat = be.fetch_wheel(name, Path(CACHE))
    with zipfile.ZipFile(fat) as z, zipfile.ZipFile(Path(CACHE) / parts[0]) as one:
        record = z.read("cffi-2.0.0.dist-info/RECORD").decode().splitlines()
        listed = {}
        for line in record:
            path, digest, size = line.rsplit(",", 2)
            listed[path] = (digest, size)
        assert set(listed) == set(z.namelist())
        for n in z.namelist():
            if n.endswith("/RECORD"):
                continue
            data = z.read(n)
            want = "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            assert listed[n] == (want, str(len(data))), n
        assert z.read("cffi/api.py") == one.read("cffi/api.py")
        assert "Tag: py3-none-manylinux2014_x86_64" in z.read("cffi-2.0.0.dist-info/WHEEL").decode()


def test_platform_mapping_agrees_with_blenders():
    """Our wheel -> Blender platform mapping (used to check the manifest) is Blender's own."""
    mod = _blender_ext()
    tags = ["manylinux2014_x86_64.manylinux_2_17_x86_64", "manylinux_2_28_aarch64", "musllinux_1_2_x86_64",
            "linux_x86_64", "win_amd64", "win_arm64", "macosx_11_0_arm64", "macosx_10_13_x86_64",
            "macosx_10_9_universal2"]
    names = [f"x-1-cp311-cp311-{t}.whl" for t in tags] + [os.path.basename(w) for w in be.read_manifest()["wheels"]]
    for name in names:
        plat = name[:-4].split("-")[-1]
        ours = be.blender_platforms(name)
        if plat == "any":
            assert ours == {"any"}
            continue
        theirs = set()
        for t in plat.split("."):
            theirs |= set(mod.blender_platforms_from_wheel_platform(t))
        assert ours == theirs, name


def test_manifest_check_names_a_missing_platform():
    manifest = be.read_manifest()
    bad = dict(manifest, wheels=[w for w in manifest["wheels"] if "win_amd64" not in w])
    with pytest.raises(SystemExit, match=r"no cffi wheel for \['windows-x64'\]"):
        be.check_wheels(bad)
    alien = dict(manifest, platforms=["linux-x64"], wheels=[w for w in manifest["wheels"] if "x86_64" in w])
    with pytest.raises(SystemExit, match="macos-x64"):
        be.check_wheels(alien)
    be.check_wheels(manifest)


def test_second_build_downloads_nothing(tmp_path, monkeypatch):
    """After one build every wheel comes from the cache: pip is never run again."""
    be.build(tmp_path / "first.zip", Path(CACHE), "zipfile")  # fills the cache if this is a fresh checkout
    real_run = subprocess.run

    def no_pip(cmd, *a, **kw):
        assert "pip" not in cmd, f"downloaded again: {cmd}"
        return real_run(cmd, *a, **kw)
    monkeypatch.setattr(be.subprocess, "run", no_pip)
    out, _ = be.build(tmp_path / "second.zip", Path(CACHE), "zipfile")
    assert out.is_file()


def test_split_platforms_one_valid_zip_each(tmp_path):
    """--split-platforms: one zip per platform, holding only that platform's cffi wheel, each accepted by Blender."""
    builder = be.bpy_builder()
    if builder is None:
        pytest.skip("bpy module not installed")
    manifest = be.read_manifest()
    out, _ = be.build(tmp_path / "gs_ibl.zip", Path(CACHE), "bpy", split_platforms=True)
    assert not out.exists()
    zips = be.split_outputs(out)
    sizes = {}
    for platform, zpath in zip(manifest["platforms"], zips):
        with zipfile.ZipFile(zpath) as z:
            names = z.namelist()
            generated = z.read("blender_manifest.toml").decode()
            assert _cffi_contents(z) == {platform: sorted(PYTHONS)}, platform
        assert {"wheels/vulkan-1.3.275.1-py3-none-any.whl", "wheels/pycparser-3.12-py3-none-any.whl"} <= set(names)
        assert f'platforms = ["{platform}"]' in generated
        r = subprocess.run([sys.executable, str(builder), "validate", str(zpath)], capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stdout + r.stderr
        sizes[platform] = zpath.stat().st_size
    print("\n[zip] split:", ", ".join(f"{p} {s / 1e6:.2f} MB" for p, s in sizes.items()))


def test_blender_validates_the_zip(tmp_path):
    builder = be.bpy_builder()
    if builder is None:
        pytest.skip("bpy module not installed")
    from pathlib import Path
    out, _ = be.build(tmp_path / "gs_ibl.zip", Path(CACHE), "zipfile")
    r = subprocess.run([sys.executable, str(builder), "validate", str(out)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


_INSTALL_SCRIPT = r"""
import glob, os, sys
import bpy
zip_path, ply_path = sys.argv[1], sys.argv[2]
assert bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                                 enable_on_install=True) == {"FINISHED"}
assert "bl_ext.user_default.gs_ibl" in sys.modules
# the bundled wheels were installed for this Python
site = glob.glob(os.path.join(os.environ["BLENDER_USER_RESOURCES"], "extensions", ".local", "lib", "python*",
                              "site-packages"))[0]
assert {"vulkan", "cffi", "pycparser"} <= set(os.listdir(site)), os.listdir(site)
# of the six cffi wheels in the zip, the one for this platform was installed, with this Python's module in it
import sysconfig
backend = [os.path.basename(b) for b in glob.glob(os.path.join(site, "_cffi_backend*"))]
assert "_cffi_backend" + sysconfig.get_config_var("EXT_SUFFIX") in backend and len(backend) == 3, backend
assert bpy.ops.gs_ibl.import_splats(native=False, filepath=ply_path) == {"FINISHED"}
obj = bpy.context.active_object
assert obj["gs_ibl"]["source"] == ply_path and len(obj.data.vertices) == 20
assert "gs_ibl_addon" not in sys.modules  # the installed copy ran, not the repository's
print("INSTALLED-OK", type(obj.data).__name__)
"""


def test_installs_with_blenders_extension_installer(tmp_path, write_3dgs_ply):
    """Blender's own installer takes the zip, installs its wheels, and the add-on imports a file under bl_ext."""
    pytest.importorskip("bpy")
    from pathlib import Path
    from gs_ibl_addon.core.synthetic import random_scene
    out, _ = be.build(tmp_path / "gs_ibl.zip", Path(CACHE), "bpy")
    ply = tmp_path / "s.ply"
    write_3dgs_ply(ply, random_scene(20, sh_degree=1))
    script = tmp_path / "install.py"
    script.write_text(_INSTALL_SCRIPT)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)
    # run from tmp so this repo's own gs_ibl_addon is not importable: only the installed copy can work
    r = subprocess.run([sys.executable, str(script), str(out), str(ply)], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "INSTALLED-OK" in r.stdout, r.stdout[-3000:] + r.stderr[-3000:]


# ---------------------------------------------------------------------------------------------- self-contained zip

# What every Blender the manifest admits provides: its own modules, and numpy (bundled by official builds, a
# dependency of Debian's package and of the bpy module).
BLENDER_PROVIDES = {"bpy", "bpy_extras", "bpy_types", "gpu", "gpu_extras", "mathutils", "bmesh", "idprop", "numpy"}
# Imported only by the command line's modules, which the extension loads but never calls there: (module, import)
# and why Blender never gets there.
CLI_ONLY = {("core.image_io", "OpenImageIO"): "reads and writes the command line's EXR/PNG files; in Blender, "
                                              "images are written by Blender itself (blender/lighting/world.py)"}
# Imported by the extension where some Blenders have them and others not; always inside a function that handles
# their absence (a fallback, or a message saying what to install).
OPTIONAL = {"zstandard": "SPZ v4: official builds and the bpy module ship it; else compression.zstd",
            "compression": "SPZ v4: Python 3.14's compression.zstd (Linux distributions' builds)",
            "OpenImageIO": "SOG's WebP outside Blender (in Blender, blender/splats/webp_decoder.py registers Blender's own)",
            "PIL": "SOG's WebP outside Blender where OpenImageIO is missing"}


def _module_name(rel: str) -> str:
    parts = rel[:-3].split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(source: str, module: str, is_package: bool) -> tuple[set[str], set[str], set[str]]:
    """(top-level names imported when the module loads, top-level names imported inside functions, modules of this
    package imported anywhere) of ``source``."""
    import ast
    tree = ast.parse(source)
    lazy_nodes = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                  for n in ast.walk(f)}
    eager, lazy, inside = set(), set(), set()
    base = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(tree):
        names = set()
        if isinstance(node, ast.Import):
            names = {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names = {node.module.split(".")[0]}
            else:
                pkg = base[:len(base) - (node.level - 1)]
                target = ".".join(pkg + (node.module.split(".") if node.module else []))
                inside.add(target)
                inside |= {f"{target}.{a.name}" for a in node.names}  # "from . import bake" names a module
        (lazy if id(node) in lazy_nodes else eager).update(names)
    return eager, lazy, inside


def _zip_modules(names: set[str], read) -> dict[str, tuple[set[str], set[str], set[str]]]:
    mods = {}
    for n in names:
        if n.endswith(".py") and not n.startswith("wheels/"):
            mods[_module_name(n)] = _imports(read(n).decode(), _module_name(n), n.endswith("__init__.py"))
    return mods


def _wheel_top_levels(z: zipfile.ZipFile, name: str) -> set[str]:
    """Top-level importable names a wheel inside the zip installs (from its RECORD)."""
    import io
    with zipfile.ZipFile(io.BytesIO(z.read(name))) as w:
        record = next(n for n in w.namelist() if n.endswith(".dist-info/RECORD"))
        tops = set()
        for line in w.read(record).decode().splitlines():
            top = line.split(",")[0].split("/")[0]
            if not top.endswith((".dist-info", ".data")):
                tops.add(top[:-3] if top.endswith(".py") else top.split(".")[0])
        return tops


def test_every_import_travels_in_the_zip(tmp_path):
    """Every module the extension imports is the standard library's, Blender's own, or in a wheel of the zip.

    The bpy module runs in our venv and sees every package we installed, so only this check (and the real-Blender
    matrix) catches an extension that imports a module no Blender has (plyfile was one)."""
    out, _ = be.build(tmp_path / "gs_ibl.zip", Path(CACHE), "zipfile")
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        mods = _zip_modules(names, z.read)
        bundled = set().union(*(_wheel_top_levels(z, n) for n in names if n.startswith("wheels/")))
    assert "vulkan" in bundled and "plyfile" in bundled and "_cffi_backend" in bundled
    # what Blender loads: the package's register() and everything it reaches inside the package
    reach, todo = set(), [m for m in mods if m in ("", "blender") or m.startswith("blender.")]
    while todo:
        m = todo.pop()
        if m in reach or m not in mods:
            continue
        reach.add(m)
        todo += [t for t in mods[m][2] if t in mods]
    assert "core.formats.ply" in reach and "core.render.renderer" in reach  # the graph is followed
    allowed = set(sys.stdlib_module_names) | BLENDER_PROVIDES | bundled
    missing = {f"{m or '__init__'}: {name}" for m in reach for name in mods[m][0] - allowed}
    missing |= {f"{m or '__init__'}: {name} (in a function)" for m in reach for name in mods[m][1] - allowed
                if name not in OPTIONAL and (m, name) not in CLI_ONLY}
    assert not missing, f"imported by the extension but in no wheel of the zip: {sorted(missing)}"
    # the command line's own modules may use more, but only what CLI_ONLY names with a reason
    other = {(m, name) for m in mods if m not in reach for name in mods[m][0] | mods[m][1]
             if name not in allowed}
    assert other <= set(CLI_ONLY), f"new imports outside Blender's reach: {sorted(other - set(CLI_ONLY))}"


def test_zstd_fallback_is_the_standard_librarys():
    """The one optional import has its fallback where the extension needs it (Python 3.14, no zstandard)."""
    from gs_ibl_addon.core.formats import zstd
    src = open(zstd.__file__).read()
    assert "import zstandard" in src and "from compression import zstd" in src
    data = bytes(range(256)) * 64
    assert zstd.decompress(zstd.compress(data, 12), len(data)) == data
    with pytest.raises(zstd.ZstdError):
        zstd.decompress(b"not zstd at all", 100)
