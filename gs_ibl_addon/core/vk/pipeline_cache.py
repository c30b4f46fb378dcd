"""A VkPipelineCache per VulkanContext, kept on disk so a new process does not compile every pipeline again.

Where: ``GS_IBL_CACHE_DIR`` wins (empty: no disk cache); else the folder given to ``set_cache_dir`` (Blender's
per-extension user folder); else ``$XDG_CACHE_HOME/gs-ibl`` or ``~/.cache/gs-ibl``. A folder that cannot be created
or written means "no disk cache" (one line on stderr per process), never an error: the in-memory cache still works.

The file, ``pipelines-<vendorID>-<deviceID>.bin``, is our header then the driver's data. Our header repeats the
device key (vendorID, deviceID, driverVersion, pipelineCacheUUID), a hash of the shipped SPIR-V with the driver's
and device's names (Mesa 22.3's lavapipe reports driverVersion 1 and the UUID "val-%s" in every release) and the
length and SHA-256 of the data; the data's own VkPipelineCacheHeaderVersionOne is checked too. Anything that does
not match is ignored (and replaced at the next save), so a driver is never handed a cache it did not write for
these shaders.
"""
from __future__ import annotations

import atexit
import hashlib
import os
import struct
import sys
import tempfile
import threading
import weakref
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Callable, Union

ENV = "GS_IBL_CACHE_DIR"
PathLike = Union[str, "os.PathLike[str]"]

_MAGIC = b"GSIBLPC1"
# magic, vendorID, deviceID, driverVersion, pipelineCacheUUID, SHA-256 of (SPIR-V, driver name and info, device
# name), data length, data SHA-256
_HEADER = struct.Struct("<8sIII16s32sQ32s")
# VkPipelineCacheHeaderVersionOne: headerSize, headerVersion, vendorID, deviceID, pipelineCacheUUID
_VK_HEADER = struct.Struct("<IIII16s")
_VK_HEADER_VERSION_ONE = 1

_configured: str | None = None
_warned = False
_live: "weakref.WeakSet[PipelineCache]" = weakref.WeakSet()


def set_cache_dir(path: PathLike | None) -> None:
    """Use ``path`` for the disk cache ("" turns it off, None restores the default); GS_IBL_CACHE_DIR still wins."""
    global _configured
    _configured = None if path is None else os.fspath(path)


def set_cache_dir_from(find: Callable[[], PathLike | None]) -> None:
    """``set_cache_dir(find())``, falling back to the default when ``find`` fails (Blender's extension folder is
    missing when the package is loaded as a legacy add-on or as the bpy module)."""
    try:
        path = find()
    except Exception:
        path = None
    set_cache_dir(path)


def default_cache_dir() -> Path:
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    base = Path(xdg) if os.path.isabs(xdg) else Path.home() / ".cache"  # the XDG spec ignores relative values
    return base / "gs-ibl"


def cache_dir() -> Path | None:
    """The folder in use now, or None when the disk cache is off."""
    env = os.environ.get(ENV)
    chosen = env if env is not None else _configured
    if chosen is None:
        return default_cache_dir()
    return Path(chosen) if chosen else None


@lru_cache(maxsize=1)
def spirv_hash() -> bytes:
    """SHA-256 over the shipped shaders: a new SPIR-V set starts a new file instead of growing the old one with
    pipelines that are never asked for again."""
    h = hashlib.sha256()
    folder = resources.files(__package__.rsplit(".", 2)[0]).joinpath("shaders")
    for f in sorted((f for f in folder.iterdir() if f.name.endswith(".spv")), key=lambda f: f.name):
        data = f.read_bytes()
        h.update(f.name.encode() + b"\0" + struct.pack("<Q", len(data)) + data)
    return h.digest()


def _driver_names(vk, physical_device, props) -> bytes:
    ffi = vk.ffi
    name = props.deviceName
    names = [name.encode() if isinstance(name, str) else ffi.string(name)]
    if vk.VK_VERSION_MINOR(props.apiVersion) >= 2 or vk.VK_VERSION_MAJOR(props.apiVersion) > 1:
        driver = ffi.new("VkPhysicalDeviceDriverProperties*")
        driver.sType = vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES
        props2 = ffi.new("VkPhysicalDeviceProperties2*")
        props2.sType = vk.VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2
        props2.pNext = driver
        vk.vkGetPhysicalDeviceProperties2(physical_device, props2)
        names += [str(int(driver.driverID)).encode(), ffi.string(driver.driverName), ffi.string(driver.driverInfo)]
    return b"\0".join(names)


def _warn_once(message: str) -> None:
    global _warned
    if not _warned:
        _warned = True
        print(f"gs-ibl: {message}; compute pipelines are not cached on disk", file=sys.stderr)


class PipelineCache:
    """The VkPipelineCache of one device (``handle``: pass it to vkCreateComputePipelines, None if it could not be
    made), loaded from and saved to its file."""

    def __init__(self, vk, physical_device, device) -> None:
        self.vk, self.device = vk, device
        self.handle = None
        self._lock = threading.Lock()
        props = vk.vkGetPhysicalDeviceProperties(physical_device)
        uuid = bytes(vk.ffi.buffer(props.pipelineCacheUUID))
        self.key = (int(props.vendorID), int(props.deviceID), int(props.driverVersion), uuid, b"")
        folder = cache_dir()
        try:
            build = hashlib.sha256(spirv_hash() + _driver_names(vk, physical_device, props)).digest()
        except Exception:
            folder = None  # no shaders to hash (pipelines.py will say so): nothing to key a file with
        else:
            self.key = self.key[:4] + (build,)
        self.path: Path | None = folder / f"pipelines-{self.key[0]:04x}-{self.key[1]:04x}.bin" if folder else None
        data = self._read() if self.path else b""
        self.loaded_bytes = len(data)
        # the size of the driver's data as it is on disk; None: no valid file there yet, so the next save writes
        self._saved_size: int | None = len(data) if data else None
        try:
            self.handle = self._create(data)
        except Exception:
            try:
                self.handle = self._create(b"") if data else None
                self._saved_size = None
            except Exception:
                self.handle = None  # vkCreateComputePipelines accepts no cache; only the saving is lost
        if self.handle is not None and self.path is not None:
            _live.add(self)

    def _create(self, data: bytes):
        vk, ffi = self.vk, self.vk.ffi
        # built by hand, every piece bound to a name until the call returns (the binding frees temporaries early)
        initial = ffi.from_buffer(data) if data else ffi.NULL
        info = ffi.new("VkPipelineCacheCreateInfo*")
        info.sType = vk.VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO
        info.initialDataSize = len(data)
        info.pInitialData = initial
        out = ffi.new("VkPipelineCache*")
        result = vk.lib.vkCreatePipelineCache(self.device, info, ffi.NULL, out)
        del initial, info
        if result != vk.VK_SUCCESS:
            raise vk.exception_codes.get(result, RuntimeError)(f"vkCreatePipelineCache: {result}")
        return out[0]

    def _read(self) -> bytes:
        try:
            raw = self.path.read_bytes()
        except OSError:
            return b""
        if len(raw) < _HEADER.size:
            return b""
        magic, vendor, device, driver, uuid, spirv, length, digest = _HEADER.unpack_from(raw)
        data = raw[_HEADER.size:]
        if (magic, vendor, device, driver, uuid, spirv) != (_MAGIC, *self.key) or length != len(data) \
                or hashlib.sha256(data).digest() != digest or not self._vk_header_ok(data):
            return b""
        return data

    def _vk_header_ok(self, data: bytes) -> bool:
        if len(data) < _VK_HEADER.size:
            return False
        size, version, vendor, device, uuid = _VK_HEADER.unpack_from(data)
        return (size >= _VK_HEADER.size and size <= len(data) and version == _VK_HEADER_VERSION_ONE
                and (vendor, device, uuid) == (self.key[0], self.key[1], self.key[3]))

    def _size(self) -> int:
        ffi = self.vk.ffi
        n = ffi.new("size_t*")
        self.vk.lib.vkGetPipelineCacheData(self.device, self.handle, n, ffi.NULL)
        return int(n[0])

    def _data(self) -> bytes:
        vk, ffi = self.vk, self.vk.ffi
        for _ in range(4):  # another thread may add a pipeline between the two calls: VK_INCOMPLETE, ask again
            n = ffi.new("size_t*")
            vk.lib.vkGetPipelineCacheData(self.device, self.handle, n, ffi.NULL)
            buf = ffi.new("char[]", max(1, n[0]))
            result = vk.lib.vkGetPipelineCacheData(self.device, self.handle, n, buf)
            if result == vk.VK_SUCCESS:
                return bytes(ffi.buffer(buf, n[0]))
        return b""

    def save(self) -> bool:
        """Write the driver's data when it differs in size from the file's (a new pipeline grows it; a driver that
        caches nothing, like lavapipe, is written once). Cheap when nothing changed: one size query."""
        with self._lock:
            if self.handle is None or self.path is None:
                return False
            if self._saved_size is not None and self._size() == self._saved_size:
                return False
            data = self._data()
            if not self._vk_header_ok(data):
                return False
            header = _HEADER.pack(_MAGIC, *self.key, len(data), hashlib.sha256(data).digest())
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                # a temporary in the same folder then os.replace: readers see the old file or the new, never half
                fd, tmp = tempfile.mkstemp(prefix=".pipelines-", suffix=".tmp", dir=self.path.parent)
                try:
                    with os.fdopen(fd, "wb") as f:
                        f.write(header + data)
                    os.replace(tmp, self.path)
                except BaseException:
                    try:
                        os.unlink(tmp)
                    except OSError:
                        pass
                    raise
            except OSError as e:
                _warn_once(f"cannot write {self.path.parent} ({e.strerror or e})")
                self.path = None
                _live.discard(self)
                return False
            self._saved_size = len(data)
            return True

    def close(self) -> None:
        """Save if needed, then destroy the VkPipelineCache (before its device)."""
        if self.handle is None:
            return
        try:
            self.save()
        finally:
            with self._lock:
                self.vk.vkDestroyPipelineCache(self.device, self.handle, None)
                self.handle = None
                _live.discard(self)


@atexit.register
def _save_all() -> None:
    # shared contexts (get_context) live until the process ends and are never closed: save what they compiled
    for cache in list(_live):
        try:
            cache.save()
        except Exception:
            pass
