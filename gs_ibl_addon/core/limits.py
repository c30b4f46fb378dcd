"""What a render or bake will need (GPU and host memory, output bytes), checked against the machine before any work.

The estimates are upper bounds built from the buffers the renderer and filters allocate (core/render/renderer.py,
core/probe/gpu_filters.py) and the host copies made of their results; a request above what the device's largest
device-local heap or the host's available memory holds is refused with a size that would fit. Out-of-memory
errors that still happen (other programs, drivers that overcommit) are turned into the same advice by
``out_of_memory_advice``.
"""
from __future__ import annotations

import os

# Bytes per output pixel (RGBA float32 image, depth) and per splat (pos_op, scale, rot, prepared, keys, rects...),
# plus the tile-instance buffers (key, value, sorter scratch) the renderer starts with: 4 per splat, 8 bytes each,
# doubled by the sorter.
GPU_BYTES_PER_PIXEL = 16 + 4
GPU_BYTES_PER_SPLAT = 16 * 3 + 80 + 4 * 4 + 48 + 4 * 8 * 2
# Host: the read-back image and its stacked copy (float32 RGBA twice) per cube pixel, and the lat-long resampling
# (4N x 2N texels: directions, face indices, bilinear weights and taps; 282 bytes each measured with tracemalloc
# for cube_to_latlong, rounded up) per face of side N.
HOST_BYTES_PER_PIXEL = 32
HOST_BYTES_PER_LATLONG_TEXEL = 288


class TooBig(ValueError):
    """A size the machine cannot hold: the message names the option, what it would need and what fits."""

    def __init__(self, option: str, value: int, message: str) -> None:
        self.option, self.value = option, value
        super().__init__(message)


def cube_bytes(face: int, irradiance: int, splats: int = 0, sh_coeffs: int = 16, glossy: bool = False
               ) -> tuple[int, int]:
    """(GPU bytes, host bytes) a probe of ``face``^2 radiance and ``irradiance``^2 irradiance faces needs."""
    pixels = 6 * face * face
    irr = 6 * irradiance * irradiance
    ggx = sum(6 * max(4, face >> k) ** 2 for k in range(5)) if glossy else 0
    gpu = pixels * GPU_BYTES_PER_PIXEL + (irr + ggx) * 16 + splats * (GPU_BYTES_PER_SPLAT + 12 * sh_coeffs)
    host = pixels * HOST_BYTES_PER_PIXEL + 8 * face * face * HOST_BYTES_PER_LATLONG_TEXEL + (irr + ggx) * 16 * 3
    return gpu, host


def image_bytes(width: int, height: int, splats: int = 0, sh_coeffs: int = 16) -> tuple[int, int]:
    """(GPU bytes, host bytes) of one pinhole render."""
    pixels = width * height
    return (pixels * GPU_BYTES_PER_PIXEL + splats * (GPU_BYTES_PER_SPLAT + 12 * sh_coeffs),
            pixels * HOST_BYTES_PER_PIXEL * 2)


def exr_bytes(width: int, height: int, channels: int, half: bool = False) -> int:
    """Upper bound of an EXR's size: uncompressed pixels plus a header's worth."""
    return width * height * channels * (2 if half else 4) + 4096


def host_available() -> int | None:
    """Bytes of memory the host can still give (Linux MemAvailable, else physical memory; None if unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def device_local_bytes(ctx) -> int:
    """Size of the device's largest device-local memory heap (what one device can hold at most)."""
    vk = ctx.vk
    mp = ctx.memory_properties
    sizes = [mp.memoryHeaps[i].size for i in range(mp.memoryHeapCount)
             if mp.memoryHeaps[i].flags & vk.VK_MEMORY_HEAP_DEVICE_LOCAL_BIT]
    return int(max(sizes or [mp.memoryHeaps[i].size for i in range(mp.memoryHeapCount)]))


def _mib(n: float) -> str:
    return f"{n / 2**30:,.1f} GiB" if n >= 2**30 else f"{n / 2**20:,.0f} MiB"


def check_fits(option: str, value: int, need: tuple[int, int], shrink, ctx=None, what: str = "") -> None:
    """Refuse ``option value`` when its (GPU, host) bytes exceed the device heap or the host's available memory.

    ``shrink(v)`` gives the need at a smaller value v, to name the largest power of two that fits.
    """
    gpu_have = device_local_bytes(ctx) if ctx is not None else None
    host_have = host_available()
    gpu, host = need

    def fits(g: int, h: int) -> bool:
        return (gpu_have is None or g <= gpu_have) and (host_have is None or h <= host_have)

    if fits(gpu, host):
        return
    v = 1
    while v * 2 < value and fits(*shrink(v * 2)):
        v *= 2
    if gpu_have is not None and gpu > gpu_have:
        need_text, where = _mib(gpu), f"the GPU ({ctx.device_name}) has {_mib(gpu_have)}"
    else:
        need_text, where = _mib(host), f"this computer has {_mib(host_have)} free"
    raise TooBig(option, value, f"{value}{what} needs about {need_text} of memory but {where}; use {v} or less")


def out_of_memory_advice(error: BaseException, what: str, advice: str) -> MemoryError | None:
    """A MemoryError with advice for an out-of-memory error (numpy's, ours or Vulkan's); None for other errors."""
    name = type(error).__name__
    if isinstance(error, MemoryError) or "OutOfDeviceMemory" in name or "OutOfHostMemory" in name \
            or "OutOfPoolMemory" in name:
        return MemoryError(f"out of memory {what} ({name}: {str(error)[:120] or 'no detail'}); {advice}")
    return None

