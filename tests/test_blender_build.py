"""The extension zip: layout Blender needs, wheels bundled, exclusions, and Blender's own validator."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import zipfile

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


def test_exclude_matcher_agrees_with_blenders():
    builder = be.bpy_builder()
    if builder is None:
        pytest.skip("bpy module not installed")
    spec = importlib.util.spec_from_file_location("blender_ext", builder)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["blender_ext"] = mod
    spec.loader.exec_module(mod)
    patterns = be.read_manifest()["build"]["paths_exclude_pattern"] + ["/shaders/*.comp", "docs/"]
    matcher = mod.PathPatternMatch(patterns)
    paths = ["__init__.py", "__pycache__/", "core/__pycache__/", "core/__pycache__/x.pyc", "core/scene.py", "x.pyc",
             ".hidden", "core/.git/", "tests/", "core/tests/", "tests/a.py", "shaders/a.spv", "shaders/a.comp",
             "core/shaders/a.comp", "docs/", "core/docs/", "docs", "wheels/a.whl"]
    for p in paths:
        is_dir = p.endswith("/")
        assert be.excluded(p.rstrip("/"), is_dir, patterns) == matcher.test_path(p), p


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
assert bpy.ops.gs_ibl.import_splats(filepath=ply_path) == {"FINISHED"}
obj = bpy.context.active_object
assert obj["gs_ibl"]["source"] == ply_path and len(obj.data.vertices) == 20
assert "gs_ibl_addon" not in sys.modules  # the installed copy ran, not the repository's
print("INSTALLED-OK", type(obj.data).__name__)
"""


def test_installs_with_blenders_extension_installer(tmp_path):
    """Blender's own installer takes the zip, installs its wheels, and the add-on imports a file under bl_ext."""
    pytest.importorskip("bpy")
    from pathlib import Path
    from test_blender_addon import random_scene, write_3dgs_ply
    out, _ = be.build(tmp_path / "gs_ibl.zip", Path(CACHE), "bpy")
    ply = tmp_path / "s.ply"
    write_3dgs_ply(ply, random_scene(20))
    script = tmp_path / "install.py"
    script.write_text(_INSTALL_SCRIPT)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)
    # run from tmp so this repo's own gs_ibl_addon is not importable: only the installed copy can work
    r = subprocess.run([sys.executable, str(script), str(out), str(ply)], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "INSTALLED-OK" in r.stdout, r.stdout[-3000:] + r.stderr[-3000:]
