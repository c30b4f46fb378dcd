"""Niantic SPZ: quantised splats, versions 2 and 3 (one gzip stream) and 4 (ZSTD streams with a plain header).

Versions 2/3: the whole file is gzip; inside, a 16-byte header ``<IIIBBBB``: magic 0x5053474e ("NGSP"), version,
point count, SH degree, fractional bits, flags, reserved; then the attributes one after the other, each for all
points: positions (3 x 24-bit signed fixed point, ``fractional bits`` after the point), alphas (u8 =
sigmoid(opacity) * 255), colours (3 x u8 = f_dc * 0.15 * 255 + 127.5), scales (3 x u8 = (log scale + 10) * 16),
rotations (v2: x, y, z of the quaternion with w >= 0, u8 = q * 127.5 + 127.5; v3: "smallest three" in one
little-endian u32: 2 bits for the index of the largest of (x, y, z, w), then the other three in that order,
each a sign bit and 9 bits of |q| / sqrt(1/2)), then SH rest coefficients (u8 = x * 128 + 128, coefficient-major,
colour channel fastest).

Version 4: a 32-byte plain header ``<IIIBBBBI12x`` (magic, version, count, SH degree, fractional bits, flags,
number of streams, byte offset of the table of contents); optional extension records ``<II`` (type, length) +
payload between byte 32 and the table; the table: per stream ``<QQ`` (compressed, uncompressed size); then each
attribute (in the order above, the SH stream left out for degree 0) as its own ZSTD frame.

Coordinates: the SPZ specification says the stored data is RUB (x right, y up, z back: OpenGL / three.js), while
3DGS PLY data and so SplatScene is RDF (COLMAP: y down, z forward). Niantic's library converts on request;
some writers (PlayCanvas splat-transform / SuperSplat, and spz's own ply_to_spz tool) store PLY data unconverted.
The file cannot tell them apart (except through the Adobe coordinate-system extension of version 4, which we
honour). We follow the specification: by default the data is read as RUB and turned into RDF (y and z negated,
quaternion and SH changed to match), and ``write_spz`` writes RUB. Pass ``coordinates="RDF"`` to read a file
written without conversion (it appears upside down otherwise).
"""
from __future__ import annotations

import gzip
import os
from functools import partial
import struct
import zlib

import numpy as np

from ..scene import SplatScene
from ..sh import degree_of, sh_basis
from . import zstd
from .checks import check_input, fail

MAGIC = 0x5053474E
COLOR_SCALE = 0.15  # SPZ stores f_dc * 0.15 (not SH_C0) so DC colours a little outside [0, 1] survive
_SQRT1_2 = np.float32(np.sqrt(0.5))
_SH_DIM = {0: 0, 1: 3, 2: 8, 3: 15, 4: 24}  # SH rest coefficients per channel, by degree
_LEGACY_HEADER = struct.Struct("<IIIBBBB")
_V4_HEADER = struct.Struct("<IIIBBBBI12x")
_EXT_COORDINATE_SYSTEM = 0xADBE0003  # SPZ_ADOBE_coordinate_system, payload: u32 enum
# spz's CoordinateSystem enum, standard family (the rotated family swaps y and z; not supported here).
_COORDINATE_SYSTEMS = {1: "LDB", 2: "RDB", 3: "LUB", 4: "RUB", 5: "LDF", 6: "RDF", 7: "LUF", 8: "RUF"}
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], np.intp)
_ALPHA_EPS = 0.25 / 255.0  # a quarter step: inside the byte's rounding interval, so it re-encodes to the same byte
_REEXPORT = "re-export the .spz, or export a 3DGS PLY instead"

_fail = partial(fail, todo=_REEXPORT)  # this format's usual advice; a call passes todo= for other advice


def _axis_flips(system: str) -> np.ndarray:
    """Per-axis signs taking coordinates in ``system`` (e.g. "RUB") to RDF; their own inverse."""
    system = system.upper()
    if len(system) != 3 or system[0] not in "LR" or system[1] not in "UD" or system[2] not in "FB":
        raise ValueError(f"coordinate system {system!r} is not one of {', '.join(_COORDINATE_SYSTEMS.values())}")
    return np.array([1.0 if system[0] == "R" else -1.0, 1.0 if system[1] == "D" else -1.0,
                     1.0 if system[2] == "F" else -1.0])


def _flip(positions: np.ndarray, rot_wxyz: np.ndarray, sh_rest: np.ndarray, f: np.ndarray) -> None:
    """Apply the axis sign flips ``f`` in place. A flip pair is a 180-degree turn: x' = x * fy * fz and so on for
    the quaternion's vector part; each SH basis function is even or odd under the flip."""
    if np.all(f == 1):
        return
    positions *= f.astype(np.float32)
    rot_wxyz[:, 1:] *= np.array([f[1] * f[2], f[0] * f[2], f[0] * f[1]], np.float32)
    k = sh_rest.shape[1]
    if k:
        degree = degree_of(k + 1)
        d = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])  # a direction no basis function vanishes on
        signs = np.sign(sh_basis(d * f, degree) / sh_basis(d, degree))[1:]
        sh_rest *= signs.astype(np.float32)[None, :, None]


# ---------------------------------------------------------------- reading


def _parse_extensions(path: str, zone: bytes, base: int) -> str | None:
    """The coordinate system named by an Adobe coordinate-system record, if any; other records are skipped."""
    at, system = 0, None
    while at + 8 <= len(zone):
        kind, length = struct.unpack_from("<II", zone, at)
        payload = zone[at + 8:at + 8 + length]
        if len(payload) != length:
            raise _fail(path, f"extension record at byte {base + at} claims {length} bytes but its zone ends first")
        if kind == _EXT_COORDINATE_SYSTEM and length >= 4:
            code = struct.unpack_from("<I", payload)[0]
            if code not in _COORDINATE_SYSTEMS and code != 0:
                raise _fail(path, f"stored in coordinate system {code} (a y/z-swapped system) which this reader "
                                  "does not convert", todo="re-export it in RUB or RDF")
            system = _COORDINATE_SYSTEMS.get(code)
        at += 8 + length
    return system


def _sizes(n: int, version: int, sh_degree: int) -> list[int]:
    return [9 * n, n, 3 * n, 3 * n, (3 if version == 2 else 4) * n, _SH_DIM[sh_degree] * 3 * n]


def _check_header(path: str, version: int, n: int, sh_degree: int, allowed: tuple[int, ...]) -> None:
    if version not in allowed:
        what = "gzip-compressed" if allowed == (2, 3) else "uncompressed-header (NGSP)"
        raise _fail(path, f"SPZ version {version} in a {what} file; this reader handles versions 2 and 3 "
                          "(gzip) and 4 (NGSP)", todo="convert it with a current spz or splat-transform")
    if n == 0:
        raise _fail(path, "the header says the file holds 0 splats")
    if sh_degree not in _SH_DIM:
        raise _fail(path, f"SH degree {sh_degree} in the header; SPZ allows 0 to 4")


def _read_legacy(path: str, raw: bytes) -> tuple[int, int, int, int, int, list, str | None]:
    try:
        data = gzip.decompress(raw)
    except (OSError, EOFError, zlib.error) as e:
        raise _fail(path, f"the gzip stream is truncated or damaged ({e})") from None
    if len(data) < _LEGACY_HEADER.size:
        raise _fail(path, f"only {len(data)} bytes after decompression; the header alone is {_LEGACY_HEADER.size}")
    magic, version, n, sh_degree, frac, flags, _ = _LEGACY_HEADER.unpack_from(data)
    if magic != MAGIC:
        raise _fail(path, f"bad magic 0x{magic:08x} inside the gzip stream (expected 0x{MAGIC:08x}, 'NGSP'): "
                          "not an SPZ file")
    _check_header(path, version, n, sh_degree, (2, 3))
    sizes = _sizes(n, version, sh_degree)
    need = _LEGACY_HEADER.size + sum(sizes)
    if len(data) < need:
        raise _fail(path, f"the data ends after {len(data)} of the {need} bytes that {n} splats need: truncated")
    if len(data) > need and not flags & 0x2:
        raise _fail(path, f"{len(data) - need} bytes follow the data of the {n} splats the header announces: "
                          "the point count is wrong or the file is damaged")
    streams, at, view = [], _LEGACY_HEADER.size, memoryview(data)  # views, not copies, of the attributes
    for size in sizes:
        streams.append(view[at:at + size])
        at += size
    system = _parse_extensions(path, data[need:], need) if flags & 0x2 else None  # legacy: records after the data
    return version, n, sh_degree, frac, flags, streams, system


def _read_v4(path: str, raw: bytes) -> tuple[int, int, int, int, int, list, str | None]:
    if len(raw) < _V4_HEADER.size:
        raise _fail(path, f"only {len(raw)} bytes; a version 4 header is {_V4_HEADER.size}: truncated")
    magic, version, n, sh_degree, frac, flags, n_streams, toc = _V4_HEADER.unpack_from(raw)
    _check_header(path, version, n, sh_degree, (4,))
    sizes = [s for s in _sizes(n, version, sh_degree) if s]
    if n_streams != len(sizes):
        raise _fail(path, f"{n_streams} attribute streams; SH degree {sh_degree} needs {len(sizes)}")
    toc_end = toc + 16 * n_streams
    if toc < _V4_HEADER.size or toc_end > len(raw):
        raise _fail(path, f"the table of contents at byte {toc} lies outside the {len(raw)}-byte file: "
                          "truncated or damaged")
    system = _parse_extensions(path, raw[_V4_HEADER.size:toc], _V4_HEADER.size) if flags & 0x2 else None
    streams, at = [], toc_end
    for i, size in enumerate(sizes):
        packed, unpacked = struct.unpack_from("<QQ", raw, toc + 16 * i)
        if unpacked != size:
            raise _fail(path, f"stream {i} holds {unpacked} bytes; {n} splats need {size}: "
                              "wrong point count or damaged")
        if at + packed > len(raw):
            raise _fail(path, f"stream {i} ends at byte {at + packed}, past the end of the {len(raw)}-byte file: "
                              "truncated")
        try:
            out = zstd.decompress(raw[at:at + packed], size)
        except zstd.ZstdMissing as e:
            raise _fail(path, f"SPZ version 4 is ZSTD-compressed and {e}",
                        todo="install the 'zstandard' package, or convert the file to SPZ version 3 or PLY") from None
        except zstd.ZstdError as e:
            raise _fail(path, f"stream {i} does not decompress ({e})") from None
        if len(out) != size:
            raise _fail(path, f"stream {i} decompresses to {len(out)} bytes, expected {size}")
        streams.append(out)
        at += packed
    if at != len(raw):
        raise _fail(path, f"{len(raw) - at} bytes follow the last stream: damaged")
    streams += [b""] * (6 - len(streams))
    return version, n, sh_degree, frac, flags, streams, system


def read_spz(path: str | os.PathLike, coordinates: str | None = None) -> SplatScene:
    """Decode an SPZ file (version 2, 3 or 4) into an activated SplatScene in RDF (3DGS PLY) coordinates.

    ``coordinates`` is the system the file's data is in; by default the file's coordinate-system extension,
    else RUB as the SPZ specification says. Use "RDF" for files written from PLY data without conversion.
    """
    path = check_input(path)
    with open(path, "rb") as f:
        raw = f.read()
    if raw[:2] == b"\x1f\x8b":
        version, n, sh_degree, frac, _flags, streams, system = _read_legacy(path, raw)
    elif raw[:4] == struct.pack("<I", MAGIC):
        version, n, sh_degree, frac, _flags, streams, system = _read_v4(path, raw)
    else:
        raise _fail(path, f"starts with {raw[:4]!r}, neither gzip (SPZ 2/3) nor 'NGSP' (SPZ 4): not an SPZ file")
    flips = _axis_flips(coordinates or system or "RUB")
    pos_b, alpha_b, colour_b, scale_b, rot_b, sh_b = (np.frombuffer(s, np.uint8) for s in streams)

    p = pos_b.reshape(n, 3, 3).astype(np.int32)
    fixed = p[..., 0] | (p[..., 1] << 8) | (p[..., 2] << 16)
    fixed -= (fixed & 0x800000) << 1  # sign-extend 24 bits
    positions = (fixed.astype(np.float64) / float(1 << frac)).astype(np.float32)
    opacities = np.clip(alpha_b.astype(np.float32) / 255.0, _ALPHA_EPS, 1 - _ALPHA_EPS)
    dc = (colour_b.reshape(n, 3).astype(np.float32) / 255.0 - 0.5) / np.float32(COLOR_SCALE)
    scales = np.exp(scale_b.reshape(n, 3).astype(np.float32) / 16.0 - 10.0)
    rotations = _unpack_v3(rot_b) if version >= 3 else _unpack_v2(rot_b)

    dim = _SH_DIM[sh_degree]
    keep = min(dim, 15)  # SplatScene (like 3DGS) stops at degree 3
    repairs = {"sh_degree_4_dropped": n} if dim > keep else {}
    sh = np.empty((n, 1 + keep, 3), np.float32)
    sh[:, 0] = dc
    rest = sh[:, 1:]
    # Filled in place (cast on assignment, exact power-of-two scaling) so no full-size float temporaries are made.
    rest[...] = sh_b.reshape(n, dim, 3)[:, :keep]
    rest -= np.float32(128.0)
    rest *= np.float32(1.0 / 128.0)
    _flip(positions, rotations, rest, flips)
    return SplatScene(positions, scales.astype(np.float32), rotations, opacities, sh, source=path, repairs=repairs)


def _xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(q[:, [3, 0, 1, 2]])


def _unpack_v2(b: np.ndarray) -> np.ndarray:
    xyz = b.reshape(-1, 3).astype(np.float32) / 127.5 - 1.0
    w = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", xyz, xyz)))
    q = np.concatenate([w[:, None], xyz], 1)
    return (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32)


def _unpack_v3(b: np.ndarray) -> np.ndarray:
    comp = b.view("<u4").astype(np.uint32)
    largest = (comp >> np.uint32(30)).astype(np.intp)
    vals = np.empty((len(comp), 3), np.float32)
    for slot, shift in enumerate((20, 10, 0)):  # the first of the three others sits in the highest bits
        field = comp >> np.uint32(shift)
        mag = (field & np.uint32(511)).astype(np.float32) * (_SQRT1_2 / np.float32(511))
        vals[:, slot] = np.where(field & np.uint32(512), -mag, mag)
    q = np.empty((len(comp), 4), np.float32)
    rows = np.arange(len(comp))
    q[rows[:, None], _OTHERS[largest]] = vals
    q[rows, largest] = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", vals, vals)))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return _xyzw_to_wxyz(q)


# ---------------------------------------------------------------- writing


def _quantise_sh(x: np.ndarray, bits: int) -> np.ndarray:
    bucket = 1 << (8 - bits)
    q = np.round(x * 128.0) + 128.0
    q = (q + bucket // 2) // bucket * bucket
    return np.clip(q, 0, 255).astype(np.uint8)


def write_spz(path: str | os.PathLike, scene: SplatScene, version: int = 3, coordinates: str = "RUB",
              sh1_bits: int = 5, sh_rest_bits: int = 4) -> None:
    """Write ``scene`` (RDF, as every SplatScene) as SPZ ``version`` 2, 3 or 4 with data in ``coordinates``.

    Quantisation: positions 24-bit fixed point (12 fractional bits, fewer if the scene reaches past +-2048),
    8 bits for alpha, colour and log scale, SH degree 1 to ``sh1_bits`` and higher degrees to ``sh_rest_bits``.
    """
    path = os.fspath(path)
    if version not in (2, 3, 4):
        raise ValueError(f"SPZ version {version} cannot be written (2, 3 or 4)")
    if not (1 <= sh1_bits <= 8 and 1 <= sh_rest_bits <= 8):
        raise ValueError("sh1_bits and sh_rest_bits must be 1..8")
    n = scene.count
    if n == 0:
        raise ValueError(f"{path}: the scene has no splats to write")
    positions = np.array(scene.positions, np.float64)
    rotations = np.array(scene.rotations, np.float32)
    rest = np.array(scene.sh[:, 1:], np.float32)
    _flip(positions, rotations, rest, _axis_flips(coordinates))

    reach = float(np.abs(positions).max())
    frac = 12
    while frac > 0 and reach * (1 << frac) >= (1 << 23) - 1:
        frac -= 1
    if reach * (1 << frac) >= (1 << 23) - 1:
        raise ValueError(f"{path}: positions reach {reach:g}, past SPZ's 24-bit fixed-point range")
    fixed = np.round(positions * (1 << frac)).astype(np.int64) & 0xFFFFFF
    pos_b = np.stack([fixed & 0xFF, (fixed >> 8) & 0xFF, fixed >> 16], -1).astype(np.uint8)
    alpha_b = np.clip(np.round(np.asarray(scene.opacities, np.float64) * 255.0), 0, 255).astype(np.uint8)
    colour = scene.sh[:, 0].astype(np.float64) * (COLOR_SCALE * 255.0) + 127.5
    colour_b = np.clip(np.round(colour), 0, 255).astype(np.uint8)
    log_s = np.log(np.maximum(np.asarray(scene.scales, np.float64), 1e-30))
    scale_b = np.clip(np.round((log_s + 10.0) * 16.0), 0, 255).astype(np.uint8)
    rot_b = _pack_v3(rotations) if version >= 3 else _pack_v2(rotations)
    k = rest.shape[1]
    sh_b = np.empty((n, k, 3), np.uint8)
    if k:
        sh_b[:, :3] = _quantise_sh(rest[:, :3], sh1_bits)
        sh_b[:, 3:] = _quantise_sh(rest[:, 3:], sh_rest_bits)
    streams = [a.tobytes() for a in (pos_b, alpha_b, colour_b, scale_b, rot_b, sh_b)]
    degree = scene.sh_degree

    if version < 4:
        header = _LEGACY_HEADER.pack(MAGIC, version, n, degree, frac, 0, 0)
        data = gzip.compress(header + b"".join(streams), compresslevel=6, mtime=0)
    else:
        streams = [s for s in streams if s]
        packed = [zstd.compress(s, 12) for s in streams]
        toc = b"".join(struct.pack("<QQ", len(c), len(s)) for c, s in zip(packed, streams))
        data = _V4_HEADER.pack(MAGIC, 4, n, degree, frac, 0, len(streams), _V4_HEADER.size) + toc + b"".join(packed)
    with open(path, "wb") as f:
        f.write(data)


def _pack_v2(q_wxyz: np.ndarray) -> np.ndarray:
    q = q_wxyz.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return np.clip(np.round(q[:, 1:] * 127.5 + 127.5), 0, 255).astype(np.uint8)


def _pack_v3(q_wxyz: np.ndarray) -> np.ndarray:
    q = q_wxyz[:, [1, 2, 3, 0]].astype(np.float64)  # SPZ order x, y, z, w
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    largest = np.argmax(np.abs(q), 1)
    rows = np.arange(len(q))
    q *= np.where(q[rows, largest] < 0, -1.0, 1.0)[:, None]
    others = q[rows[:, None], _OTHERS[largest]]
    mag = np.minimum(np.floor(511.0 * np.abs(others) / np.sqrt(0.5) + 0.5), 511).astype(np.uint32)
    field = mag | (np.uint32(512) * (others < 0))
    comp = (largest.astype(np.uint32) << np.uint32(30)) | (field[:, 0] << np.uint32(20)) \
        | (field[:, 1] << np.uint32(10)) | field[:, 2]
    return comp.astype("<u4").view(np.uint8).reshape(-1, 4)
