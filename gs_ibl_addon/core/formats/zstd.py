"""ZSTD for SPZ version 4, from whichever implementation this Python has.

Official Blender builds and the bpy module bundle the ``zstandard`` package; Linux distributions' Blender runs on
the system Python, which from 3.14 has ``compression.zstd`` in the standard library and may lack ``zstandard``
(Debian's 5.2 on 3.14). Neither is a wheel of ours: zstandard is compiled, one wheel per platform and Python.
"""
from __future__ import annotations


class ZstdError(ValueError):
    """Data that does not decompress."""


class ZstdMissing(ImportError):
    """Neither implementation is importable."""


def _backend():
    try:
        import zstandard
        return zstandard
    except ImportError:
        pass
    try:
        from compression import zstd  # Python 3.14+
        return zstd
    except ImportError:
        raise ZstdMissing("no ZSTD implementation: this Python has neither the 'zstandard' package nor "
                          "compression.zstd (Python 3.14+)") from None


def decompress(data: bytes, size: int) -> bytes:
    """``data`` decompressed, at most ``size`` bytes (a damaged stream cannot claim more memory than that)."""
    z = _backend()
    try:
        if z.__name__ == "zstandard":
            return z.ZstdDecompressor().decompress(data, max_output_size=size)
        return z.ZstdDecompressor().decompress(data, max_length=size)
    except z.ZstdError as e:
        raise ZstdError(str(e)) from None


def compress(data: bytes, level: int) -> bytes:
    z = _backend()
    if z.__name__ == "zstandard":
        return z.ZstdCompressor(level=level).compress(data)
    return z.compress(data, level=level)
