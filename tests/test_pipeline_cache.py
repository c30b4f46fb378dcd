"""The on-disk Vulkan pipeline cache (core/vk/pipeline_cache.py), on the real device (lavapipe here): written with a
valid header, loaded by a fresh process without changing a pixel, anything wrong in the file ignored and replaced,
and off when its folder cannot be written or GS_IBL_CACHE_DIR is empty."""
import hashlib
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from gs_ibl_addon.core.vk import KERNELS, VulkanContext
from gs_ibl_addon.core.vk import pipeline_cache
from gs_ibl_addon.core.vk.pipelines import get_pipeline

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FEW = ("gs_preprocess", "gs_raster", "scan_block")


def _parse(path):
    """Our header and the driver's VkPipelineCacheHeaderVersionOne, checked as the loader checks them."""
    raw = path.read_bytes()
    magic, vendor, device, driver, uuid, build, length, digest = pipeline_cache._HEADER.unpack_from(raw)
    data = raw[pipeline_cache._HEADER.size:]
    assert magic == b"GSIBLPC1" and length == len(data) and hashlib.sha256(data).digest() == digest
    size, version, vk_vendor, vk_device, vk_uuid = struct.unpack_from("<IIII16s", data)
    assert size >= 32 and version == 1 and (vk_vendor, vk_device, vk_uuid) == (vendor, device, uuid)
    return (vendor, device, driver, uuid, build), data


def _context_with_pipelines(names=FEW) -> VulkanContext:
    ctx = VulkanContext()
    for n in names:
        get_pipeline(ctx, KERNELS[n])
    return ctx


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv("GS_IBL_CACHE_DIR", str(d))
    return d


@pytest.fixture
def written(cache_dir):
    """A cache file written by a context that made a few pipelines and closed."""
    ctx = _context_with_pipelines()
    path = ctx.pipeline_cache.path
    ctx.close()
    return path


def test_fresh_context_writes_a_file_with_a_valid_header(cache_dir):
    ctx = _context_with_pipelines()
    try:
        path = ctx.pipeline_cache.path
        assert path.parent == cache_dir and path.exists()  # written right after the pipelines, before close
        key, _ = _parse(path)
        props = ctx.vk.vkGetPhysicalDeviceProperties(ctx.physical_device)
        assert key[:3] == (props.vendorID, props.deviceID, props.driverVersion)
        assert key == ctx.pipeline_cache.key
        assert not [p for p in cache_dir.iterdir() if p.name.endswith(".tmp")]  # no temporary left behind
    finally:
        ctx.close()


_RENDER = """
import sys, numpy as np
from gs_ibl_addon.core.vk import VulkanContext
from gs_ibl_addon.core.render.renderer import SplatRenderer
from gs_ibl_addon.core.render.views import ViewBatch
from gs_ibl_addon.core.synthetic import random_scene
ctx = VulkanContext()
r = SplatRenderer(random_scene(300, seed=5, sh_degree=1, extent=2.0), ctx)
img = np.stack(r.render(ViewBatch.cubemap([0.1, 0.0, -0.1], 16)).images)
r.close()
loaded, rewrote = ctx.pipeline_cache.loaded_bytes, ctx.pipeline_cache.save()
ctx.close()
np.save(sys.argv[1], img)
print(loaded, rewrote)
"""


def _render_in_subprocess(out, cache: str) -> tuple[np.ndarray, int, bool]:
    env = dict(os.environ, GS_IBL_CACHE_DIR=cache, PYTHONPATH=ROOT)
    run = subprocess.run([sys.executable, "-c", _RENDER, str(out)], env=env, cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    loaded, rewrote = run.stdout.split()
    return np.load(out), int(loaded), rewrote == "True"


def test_a_fresh_process_loads_the_cache_and_renders_the_same_pixels(tmp_path):
    cache = tmp_path / "cache"
    cold, loaded, _ = _render_in_subprocess(tmp_path / "cold.npy", str(cache))
    assert loaded == 0
    key, data = _parse(next(cache.iterdir()))
    warm, loaded, rewrote = _render_in_subprocess(tmp_path / "warm.npy", str(cache))
    assert loaded == len(data) and not rewrote  # nothing new compiled, nothing written again
    none, loaded, _ = _render_in_subprocess(tmp_path / "none.npy", "")
    assert loaded == 0
    assert cold.shape == (6, 16, 16, 4) and cold[..., 3].max() > 0
    np.testing.assert_array_equal(warm, none)
    np.testing.assert_array_equal(cold, none)


def _corrupt(raw: bytes) -> bytes:
    return raw[:-1] + bytes([raw[-1] ^ 0xFF])


def _truncated(raw: bytes) -> bytes:
    return raw[: pipeline_cache._HEADER.size + 10]


def _foreign_device(raw: bytes) -> bytes:
    # the driver's header names another vendor, and ours is consistent with those bytes (right length and SHA):
    # only the check of the Vulkan header can refuse it
    data = bytearray(raw[pipeline_cache._HEADER.size:])
    struct.pack_into("<I", data, 8, 0x1234)
    head = list(pipeline_cache._HEADER.unpack_from(raw))
    head[-1] = hashlib.sha256(bytes(data)).digest()
    return pipeline_cache._HEADER.pack(*head) + bytes(data)


def _other_shaders(raw: bytes) -> bytes:
    head = list(pipeline_cache._HEADER.unpack_from(raw))
    head[5] = bytes(32)
    return pipeline_cache._HEADER.pack(*head) + raw[pipeline_cache._HEADER.size:]


@pytest.mark.parametrize("damage", [_corrupt, _truncated, _foreign_device, _other_shaders, lambda raw: b"junk"],
                         ids=["corrupt", "truncated", "foreign-device", "other-shaders", "junk"])
def test_a_damaged_or_foreign_file_is_ignored_and_replaced(written, damage):
    good = written.read_bytes()
    written.write_bytes(damage(good))
    ctx = _context_with_pipelines()
    try:
        assert ctx.pipeline_cache.loaded_bytes == 0 and ctx.pipeline_cache.handle is not None
        key, _ = _parse(written)  # replaced by a valid file at the first new pipeline
        assert key == ctx.pipeline_cache.key and written.read_bytes() != damage(good)
    finally:
        ctx.close()


def test_a_folder_that_cannot_be_written_turns_the_disk_cache_off_quietly(tmp_path, monkeypatch, capfd):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("GS_IBL_CACHE_DIR", str(blocker / "cache"))  # below a file: even root cannot create it
    monkeypatch.setattr(pipeline_cache, "_warned", False)
    ctx = _context_with_pipelines()
    try:
        assert ctx.pipeline_cache.path is None and ctx.pipeline_cache.handle is not None
        get_pipeline(ctx, KERNELS["gs_emit"])
    finally:
        ctx.close()
    lines = capfd.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "not cached on disk" in lines[0], lines


def test_empty_env_turns_it_off_and_env_wins_over_set_cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(pipeline_cache, "_configured", None)
    monkeypatch.setenv("GS_IBL_CACHE_DIR", "")
    pipeline_cache.set_cache_dir(tmp_path / "set")
    assert pipeline_cache.cache_dir() is None
    ctx = _context_with_pipelines(("scan_block",))
    try:
        assert ctx.pipeline_cache.path is None and ctx.pipeline_cache.handle is not None
    finally:
        ctx.close()
    # (Mesa keeps its own shader cache in XDG_CACHE_HOME too: only ours is looked for)
    assert not (tmp_path / "xdg" / "gs-ibl").exists() and not (tmp_path / "set").exists()

    monkeypatch.delenv("GS_IBL_CACHE_DIR")
    assert pipeline_cache.cache_dir() == tmp_path / "set"
    pipeline_cache.set_cache_dir("")
    assert pipeline_cache.cache_dir() is None
    pipeline_cache.set_cache_dir_from(lambda: 1 / 0)  # Blender without an extension folder: the default
    assert pipeline_cache.cache_dir() == tmp_path / "xdg" / "gs-ibl"
    monkeypatch.setenv("GS_IBL_CACHE_DIR", str(tmp_path / "env"))
    assert pipeline_cache.cache_dir() == tmp_path / "env"
