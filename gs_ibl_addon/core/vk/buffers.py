"""Storage buffers and host transfers.

A Buffer is device-local where the device has such memory, mapped directly when it is host-visible; otherwise
writes and reads go through the context's two kept staging buffers (``staging``), in pieces of at most
STAGING_MAX. Every transfer is counted in ``ctx.stats``. ``scratch`` lends pooled buffers by size class.
Like everything in vk/, nested create-infos are bound to local names (shared/NOTES-vulkan-and-gpu.md: cffi frees
temporaries early).
"""
from __future__ import annotations

import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .commands import Recorder
from .context import VulkanContext

_serial = itertools.count(1)
STAGING_MAX = 64 << 20  # the kept staging buffers grow to this at most; larger transfers go in pieces
# A host copy of more bytes than this is split over COPY_THREADS threads (numpy copies without the GIL): one thread
# copied a 1080p camera frame's 41 MB out of the staging buffer at 8.5 GB/s on the H100 machine's host, 4.8 of its
# 6.5 ms of host time (host_profile.py, 2026-12-06). Half the cores, as memory bandwidth, not cores, bounds a copy.
PARALLEL_COPY = 8 << 20
COPY_THREADS = min(8, (os.cpu_count() or 1) // 2)
_copy_pool: ThreadPoolExecutor | None = None
_copy_pool_lock = threading.Lock()  # reads come from the overlay, bakes' workers and F12 at once


def copy_bytes(dst: np.ndarray, src: np.ndarray) -> None:
    """dst[:] = src for two 1-D uint8 arrays of one length, over COPY_THREADS threads when large."""
    global _copy_pool
    n = dst.nbytes
    if n < PARALLEL_COPY or COPY_THREADS < 2:
        dst[:] = src
        return
    with _copy_pool_lock:
        if _copy_pool is None:
            _copy_pool = ThreadPoolExecutor(COPY_THREADS, thread_name_prefix="gs-ibl-copy")
    step = -(-n // (COPY_THREADS * 4096)) * 4096  # whole pages
    for f in [_copy_pool.submit(np.copyto, dst[i:i + step], src[i:i + step]) for i in range(0, n, step)]:
        f.result()


class Buffer:
    """A storage buffer. Device-local where the device has such memory; mapped directly when it is host-visible.

    ``with Buffer(ctx, n) as b:`` destroys it when the block ends; a pooled buffer (``scratch``) goes back to
    the context's pool instead.
    """

    def __init__(self, ctx: VulkanContext, nbytes: int, name: str = "", pooled: bool = False) -> None:
        vk = ctx.vk
        self.ctx, self.name, self.serial, self.pooled = ctx, name, next(_serial), pooled
        self.nbytes = max(int(nbytes), 16)
        usage = (vk.VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT
                 | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT)
        bci = vk.VkBufferCreateInfo(size=self.nbytes, usage=usage, sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE)
        self.handle = vk.vkCreateBuffer(ctx.device, bci, None)
        req = vk.vkGetBufferMemoryRequirements(ctx.device, self.handle)
        local = vk.VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT
        host = vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
        # Host-visible device-local memory (lavapipe, resizable BAR) avoids staging copies; big buffers on a
        # discrete GPU live in plain device-local memory and go through a staging buffer.
        small = self.nbytes <= (256 << 20) or ctx.is_cpu
        choices = [local | host, local, host] if small else [local, local | host, host]
        for flags in choices:
            try:
                mtype = ctx.memory_type(req.memoryTypeBits, flags)
            except RuntimeError:
                continue
            mai = vk.VkMemoryAllocateInfo(allocationSize=req.size, memoryTypeIndex=mtype)
            try:
                self.memory = vk.vkAllocateMemory(ctx.device, mai, None)
            except Exception:
                continue
            mflags = ctx.memory_properties.memoryTypes[mtype].propertyFlags
            self.host_visible = bool(mflags & vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT)
            # Reading uncached mapped memory (a GPU's BAR window) crawls; such buffers read through a cached copy.
            self.host_cached = bool(mflags & vk.VK_MEMORY_PROPERTY_HOST_CACHED_BIT)
            break
        else:
            vk.vkDestroyBuffer(ctx.device, self.handle, None)
            raise MemoryError(f"{ctx.device_name}: cannot allocate {self.nbytes / 2**20:.1f} MiB for buffer {name!r}")
        vk.vkBindBufferMemory(ctx.device, self.handle, self.memory, 0)
        self._map = vk.vkMapMemory(ctx.device, self.memory, 0, self.nbytes, 0) if self.host_visible else None

    def write(self, data: np.ndarray | bytes, offset: int = 0) -> None:
        raw = memoryview(np.ascontiguousarray(data)).cast("B") if isinstance(data, np.ndarray) else memoryview(data)
        if offset + raw.nbytes > self.nbytes:
            raise ValueError(f"write of {raw.nbytes} bytes at {offset} overflows buffer {self.name!r} ({self.nbytes})")
        if raw.nbytes == 0:
            return
        stats = self.ctx.stats
        stats.uploads += 1
        stats.upload_bytes += raw.nbytes
        if self._map is not None:
            copy_bytes(np.frombuffer(self._map, np.uint8, raw.nbytes, offset), np.frombuffer(raw, np.uint8))
            return
        with self.ctx.lock:  # through the kept staging buffer, in pieces of at most STAGING_MAX bytes
            stage = staging(self.ctx, min(raw.nbytes, STAGING_MAX), "up")
            for start in range(0, raw.nbytes, STAGING_MAX):
                piece = raw[start:start + STAGING_MAX]
                copy_bytes(np.frombuffer(stage._map, np.uint8, piece.nbytes), np.frombuffer(piece, np.uint8))
                with Recorder(self.ctx) as rec:
                    rec.copy(stage, self, piece.nbytes, dst_offset=offset + start)

    def read(self, dtype=np.uint8, count: int | None = None, offset: int = 0,
             out: np.ndarray | None = None) -> np.ndarray:
        """``count`` values of ``dtype`` from byte ``offset`` as a new array, or into ``out`` (C-contiguous, of
        exactly those bytes; returned): host memory written before costs no page faults (renderer.render_camera)."""
        dt = np.dtype(dtype)
        n = (self.nbytes - offset) // dt.itemsize if count is None else int(count)
        nbytes = n * dt.itemsize
        if out is not None and (out.nbytes != nbytes or not out.flags.c_contiguous or not out.flags.writeable):
            raise ValueError(f"read of {nbytes} bytes from buffer {self.name!r} into an array of {out.nbytes} "
                             "(it must be C-contiguous, writeable and of exactly those bytes)")
        stats = self.ctx.stats
        stats.readbacks += 1
        stats.readback_bytes += nbytes
        # Small reads of mapped memory are direct even when uncached (a few words cost less than a copy).
        if out is None:
            out = np.empty(n, dt)
        dst = out.reshape(-1).view(np.uint8)
        if self._map is not None and (self.host_cached or nbytes <= 4096):
            copy_bytes(dst, np.frombuffer(self._map, np.uint8, nbytes, offset))
            return out
        with self.ctx.lock:
            stage = staging(self.ctx, min(nbytes, STAGING_MAX), "down")
            for start in range(0, nbytes, STAGING_MAX):
                size = min(STAGING_MAX, nbytes - start)
                with Recorder(self.ctx) as rec:
                    rec.copy(self, stage, size, src_offset=offset + start)
                copy_bytes(dst[start:start + size], np.frombuffer(stage._map, np.uint8, size))
        return out

    @staticmethod
    def staging(ctx: VulkanContext, nbytes: int, cached: bool = False) -> "Buffer":
        """A host-visible transfer buffer (the context keeps two: VulkanContext.staging)."""
        b = Buffer.__new__(Buffer)
        vk = ctx.vk
        b.ctx, b.name, b.serial, b.nbytes, b.pooled = ctx, "staging", next(_serial), max(int(nbytes), 16), False
        bci = vk.VkBufferCreateInfo(size=b.nbytes, sharingMode=vk.VK_SHARING_MODE_EXCLUSIVE,
                                    usage=vk.VK_BUFFER_USAGE_TRANSFER_SRC_BIT | vk.VK_BUFFER_USAGE_TRANSFER_DST_BIT)
        b.handle = vk.vkCreateBuffer(ctx.device, bci, None)
        req = vk.vkGetBufferMemoryRequirements(ctx.device, b.handle)
        flags = vk.VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | vk.VK_MEMORY_PROPERTY_HOST_COHERENT_BIT
        try:
            cached_bit = vk.VK_MEMORY_PROPERTY_HOST_CACHED_BIT if cached else 0
            mtype = ctx.memory_type(req.memoryTypeBits, flags | cached_bit)
        except RuntimeError:
            mtype = ctx.memory_type(req.memoryTypeBits, flags)
        mai = vk.VkMemoryAllocateInfo(allocationSize=req.size, memoryTypeIndex=mtype)
        b.memory = vk.vkAllocateMemory(ctx.device, mai, None)
        vk.vkBindBufferMemory(ctx.device, b.handle, b.memory, 0)
        b.host_visible = True
        b.host_cached = cached
        b._map = vk.vkMapMemory(ctx.device, b.memory, 0, b.nbytes, 0)
        return b

    @property
    def alive(self) -> bool:
        return self.handle is not None and self.ctx.device is not None

    def destroy(self) -> None:
        vk = self.ctx.vk
        if self.handle is None or self.ctx.device is None:
            return
        if self._map is not None:
            vk.vkUnmapMemory(self.ctx.device, self.memory)
            self._map = None
        vk.vkDestroyBuffer(self.ctx.device, self.handle, None)
        vk.vkFreeMemory(self.ctx.device, self.memory, None)
        self.handle = None

    def close(self) -> None:
        """End of this owner's use: a pooled buffer returns to the context's pool, any other is destroyed."""
        if self.pooled and self.alive:
            self.ctx.release(self)
        else:
            self.destroy()

    def __enter__(self) -> "Buffer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            if not getattr(self, "pooled", False):
                self.destroy()
        except Exception:
            pass


def staging(ctx: VulkanContext, nbytes: int, direction: str) -> Buffer:
    """The context's staging buffer for ``direction`` ('up' or 'down'), grown to at least ``nbytes`` and kept."""
    b = ctx._staging.get(direction)
    if b is None or b.nbytes < nbytes:
        if b is not None:
            b.destroy()
        size = 1 << max(16, (int(nbytes) - 1).bit_length())
        b = ctx._staging[direction] = Buffer.staging(ctx, size, cached=direction == "down")
    return b


def scratch(ctx: VulkanContext, nbytes: int, name: str = "scratch") -> Buffer:
    """A pooled storage buffer of at least ``nbytes`` (sizes rounded up to a power of two); ``close()`` gives it
    back to the context's pool and the next request of that size class reuses its memory."""
    size = 1 << max(8, (max(1, int(nbytes)) - 1).bit_length())
    free = ctx._scratch.get(size)
    if free:
        b = free.pop()
        b.name = name
        return b
    return Buffer(ctx, size, name, pooled=True)


def kept(ctx: VulkanContext, key, nbytes: int, staging: bool = False) -> Buffer:
    """A buffer the context keeps in ``ctx.cache`` under ``key``, made anew only when gone or smaller than
    ``nbytes``: a device buffer named for the key, or with ``staging`` a host-visible one to read back into. Kept so
    that what is recorded on it (filter plans, readback copies) is found again by the next bake; one bake at a time
    per context, as its recordings are."""
    b = ctx.cache.get(key)
    if b is None or not b.alive or b.nbytes < nbytes:
        if b is not None:
            b.destroy()
        name = key[0] if isinstance(key, tuple) else str(key)
        b = ctx.cache[key] = Buffer.staging(ctx, nbytes, cached=True) if staging else Buffer(ctx, nbytes, name)
    return b

