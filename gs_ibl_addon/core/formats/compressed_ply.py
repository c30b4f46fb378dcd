"""SuperSplat / PlayCanvas "compressed PLY": 256-splat chunks of quantised splats inside an ordinary PLY.

Layout (as SuperSplat and PlayCanvas splat-transform write it):

* ``chunk`` element, one row per 256 splats, float32: ``min_x..max_z`` (position range),
  ``min_scale_x..max_scale_z`` (range of the *log* scale) and, in files since 2024, ``min_r..max_b``
  (range of the DC colour ``0.5 + SH_C0 * f_dc``, not clamped to [0, 1]).
* ``vertex`` element, four uint32 per splat:
  ``packed_position`` and ``packed_scale`` are 11/10/11-bit unorms (x in the top bits) lerped in the chunk range;
  ``packed_rotation`` is smallest-three: 2 bits for the index of the largest component of (w, x, y, z), then
  the other three in that order, 10 bits each, mapping [-1/sqrt2, 1/sqrt2] to [0, 1];
  ``packed_color`` is RGBA8 (R in the top byte): RGB lerped in the chunk colour range (or the colour itself,
  clamped to [0, 1], when the chunk has no colour range) and A = sigmoid(opacity).
* optional ``sh`` element: ``f_rest_0..`` as uint8 in the 3DGS PLY order, value = (c - 0.5) * 8 with c the bucket
  centre (v + 0.5) / 256, except 0 -> -4 and 255 -> +4.

Everything is decoded with whole-array numpy operations.
"""
from __future__ import annotations

import os
from functools import partial

import numpy as np
from plyfile import PlyData, PlyElement, PlyParseError

from ..scene import SplatScene, rgb_to_sh_dc, sh_dc_to_rgb
from .checks import check_input, fail
from .ply import parse_header

CHUNK_SIZE = 256
_CHUNK_BASE = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z",
               "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z")
_CHUNK_COLOUR = ("min_r", "min_g", "min_b", "max_r", "max_g", "max_b")
_PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
_SQRT2 = np.float32(np.sqrt(2.0))
# For each index of the largest component, the other three in stored order.
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], np.intp)
# An 8-bit alpha of 0 or 255 stands for any opacity within half a step of it; keep it inside the open
# interval SplatScene promises (an opacity of exactly 0 or 1 breaks the logit other writers take).
_ALPHA_EPS = 0.25 / 255.0  # a quarter step: inside the byte's rounding interval, so it re-encodes to the same byte
_REEXPORT = "re-export it from SuperSplat or PlayCanvas splat-transform"

_fail = partial(fail, todo=_REEXPORT)  # this format's usual advice; a call passes todo= for other advice


def _unorm(packed: np.ndarray, shift: int, bits: int) -> np.ndarray:
    mask = (1 << bits) - 1
    return ((packed >> np.uint32(shift)) & np.uint32(mask)).astype(np.float32) / np.float32(mask)


def _lerp(lo: np.ndarray, hi: np.ndarray, t: np.ndarray) -> np.ndarray:
    return lo * (1 - t) + hi * t


def _column(path: str, element: PlyElement, name: str, dtype: str) -> np.ndarray:
    names = element.data.dtype.names or ()
    if name not in names:
        raise _fail(path, f"element '{element.name}' has no property '{name}' (it has {', '.join(names) or 'none'})")
    col = element.data[name]
    if col.dtype != np.dtype(dtype):
        raise _fail(path, f"property '{element.name}.{name}' is {col.dtype}, expected {np.dtype(dtype)}")
    return np.array(col)  # a copy, so no view keeps the file mapped once reading is done


def read_compressed_ply(path: str | os.PathLike) -> SplatScene:
    """Decode a SuperSplat compressed PLY into an activated SplatScene (file order kept)."""
    path = check_input(path)
    parse_header(path)  # counts against the file size before plyfile maps or allocates anything
    try:
        # Memory-mapped: plyfile then views each element as one array (without mmap it parses row by row).
        ply = PlyData.read(path, mmap=True)
    except (PlyParseError, ValueError, EOFError, OSError) as e:
        raise _fail(path, f"not a readable PLY: {e}", todo="the file is truncated or damaged; " + _REEXPORT) from None
    elements = {e.name: e for e in ply.elements}
    for name in ("chunk", "vertex"):
        if name not in elements:
            raise _fail(path, f"no '{name}' element, so this is not a SuperSplat compressed PLY "
                              f"(it has {', '.join(elements) or 'no elements'})")
    chunk, vertex = elements["chunk"], elements["vertex"]
    n = vertex.count
    n_chunks = -(-n // CHUNK_SIZE)
    if chunk.count != n_chunks:
        raise _fail(path, f"{chunk.count} chunks for {n} splats; a chunk holds {CHUNK_SIZE} splats, "
                          f"so expected {n_chunks}")

    c = {name: _column(path, chunk, name, "<f4") for name in _CHUNK_BASE}
    chunk_names = chunk.data.dtype.names or ()
    has_colour_range = all(name in chunk_names for name in _CHUNK_COLOUR)
    if has_colour_range:
        c.update({name: _column(path, chunk, name, "<f4") for name in _CHUNK_COLOUR})
    bad = ~np.all(np.isfinite(np.stack(list(c.values()), 1)), 1) if n_chunks else np.zeros(0, bool)
    if bad.any():
        raise _fail(path, f"{int(bad.sum())} chunk(s) have non-finite ranges (first: chunk {int(np.argmax(bad))})")
    packed = {name: _column(path, vertex, name, "<u4") for name in _PACKED}

    # Per-splat chunk index, expanded once and shared by every lerp.
    ci = np.repeat(np.arange(n_chunks), CHUNK_SIZE)[:n]

    def ranged(axis: str, prefix: str, t: np.ndarray) -> np.ndarray:
        lo, hi = c[f"min_{prefix}{axis}"][ci], c[f"max_{prefix}{axis}"][ci]
        return _lerp(lo, hi, t)

    pp, ps = packed["packed_position"], packed["packed_scale"]
    positions = np.stack([ranged("x", "", _unorm(pp, 21, 11)), ranged("y", "", _unorm(pp, 11, 10)),
                          ranged("z", "", _unorm(pp, 0, 11))], 1).astype(np.float32)
    log_scales = np.stack([ranged("x", "scale_", _unorm(ps, 21, 11)), ranged("y", "scale_", _unorm(ps, 11, 10)),
                           ranged("z", "scale_", _unorm(ps, 0, 11))], 1)
    scales = np.exp(log_scales).astype(np.float32)

    rotations = _unpack_rotation(packed["packed_rotation"])

    pc = packed["packed_color"]
    rgb = [_unorm(pc, 24, 8), _unorm(pc, 16, 8), _unorm(pc, 8, 8)]
    if has_colour_range:
        rgb = [ranged(ch, "", t) for ch, t in zip("rgb", rgb)]
    dc = rgb_to_sh_dc(np.stack(rgb, 1))
    opacities = np.clip(_unorm(pc, 0, 8), _ALPHA_EPS, 1 - _ALPHA_EPS).astype(np.float32)

    sh = _read_sh(path, elements.get("sh"), n)
    sh[:, 0] = dc

    bad = ~(np.isfinite(positions).all(1) & np.isfinite(scales).all(1) & (scales > 0).all(1))
    if bad.any():
        raise _fail(path, f"{int(bad.sum())} splat(s) decode to non-finite positions or zero scales "
                          f"(first: splat {int(np.argmax(bad))})")
    return SplatScene(positions, scales, rotations, opacities, sh, source=path)


def _unpack_rotation(pr: np.ndarray) -> np.ndarray:
    largest = (pr >> np.uint32(30)).astype(np.intp)
    abc = np.stack([_unorm(pr, 20, 10), _unorm(pr, 10, 10), _unorm(pr, 0, 10)], 1)
    abc = (abc - np.float32(0.5)) * _SQRT2
    q = np.empty((len(pr), 4), np.float32)
    rows = np.arange(len(pr))[:, None]
    q[rows, _OTHERS[largest]] = abc
    q[rows[:, 0], largest] = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", abc, abc)))
    # The reconstructed component makes q unit up to rounding; normalise to float32 precision.
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q


# uint8 -> SH value: bucket centres, with the end codes standing for the ends of the range [-4, 4].
_SH_LUT = ((np.arange(256, dtype=np.float32) + np.float32(0.5)) / np.float32(256.0))
_SH_LUT[0], _SH_LUT[255] = 0.0, 1.0
_SH_LUT = (_SH_LUT - np.float32(0.5)) * np.float32(8.0)


def _read_sh(path: str, element: PlyElement | None, n: int) -> np.ndarray:
    """The (n, K, 3) SH array with the rest coefficients filled in (column by column, to keep memory low)."""
    if element is None:
        return np.empty((n, 1, 3), np.float32)
    if element.count != n:
        raise _fail(path, f"the 'sh' element has {element.count} rows for {n} splats")
    names = element.data.dtype.names or ()
    if len(names) not in (9, 24, 45):
        raise _fail(path, f"the 'sh' element has {len(names)} properties; expected 9, 24 or 45 (SH degree 1, 2 or 3)")
    k = len(names) // 3
    sh = np.empty((n, 1 + k, 3), np.float32)
    for i in range(len(names)):
        # PLY order is channel-major: f_rest_{c * k + j} is coefficient j of channel c.
        c, j = divmod(i, k)
        sh[:, 1 + j, c] = _SH_LUT[_column(path, element, f"f_rest_{i}", "u1")]
    return sh


# ---------------------------------------------------------------- writing


def morton_order(positions: np.ndarray) -> np.ndarray:
    """Indices that sort splats along a 3D Morton (Z-order) curve, so each 256-splat chunk is compact in space."""
    p = np.asarray(positions, np.float64)
    if len(p) == 0:
        return np.zeros(0, np.intp)
    lo, hi = p.min(0), p.max(0)
    extent = np.where(hi - lo > 0, hi - lo, 1.0)
    q = np.clip(((p - lo) / extent * 1023.0).astype(np.uint64), 0, 1023)

    def spread(v: np.ndarray) -> np.ndarray:  # 10 bits -> every third bit of 30
        v = (v | (v << np.uint64(16))) & np.uint64(0x030000FF)
        v = (v | (v << np.uint64(8))) & np.uint64(0x0300F00F)
        v = (v | (v << np.uint64(4))) & np.uint64(0x030C30C3)
        return (v | (v << np.uint64(2))) & np.uint64(0x09249249)

    code = spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)) | (spread(q[:, 2]) << np.uint64(2))
    return np.argsort(code, kind="stable")


def _pack_unorm(t: np.ndarray, bits: int) -> np.ndarray:
    m = (1 << bits) - 1
    return np.clip(np.floor(t * m + 0.5), 0, m).astype(np.uint32)


def _normalise_in_range(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    span = hi - lo
    t = np.where(span < 1e-5, 0.0, (x - lo) / np.where(span < 1e-5, 1.0, span))
    return np.clip(t, 0.0, 1.0)


def _pack_rotation(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    largest = np.argmax(np.abs(q), 1)
    rows = np.arange(len(q))
    q = q * np.where(q[rows, largest] < 0, -1.0, 1.0)[:, None]  # -q is the same rotation; store largest >= 0
    abc = q[rows[:, None], _OTHERS[largest]] * (np.sqrt(2.0) * 0.5) + 0.5
    packed = largest.astype(np.uint32) << np.uint32(30)
    for slot, shift in enumerate((20, 10, 0)):
        packed |= _pack_unorm(abc[:, slot], 10) << np.uint32(shift)
    return packed


def write_compressed_ply(path: str | os.PathLike, scene: SplatScene, sort: bool = True) -> np.ndarray:
    """Write ``scene`` as a SuperSplat compressed PLY (with per-chunk colour ranges and SH rest, if any).

    With ``sort`` the splats are written in Morton order (as SuperSplat does), which makes chunks compact and
    so positions and scales precise; the return value is the order used (``file splat i = scene splat order[i]``).
    """
    path = os.fspath(path)
    n = scene.count
    if n == 0:
        raise ValueError(f"{path}: the scene has no splats to write")
    order = morton_order(scene.positions) if sort else np.arange(n)
    n_chunks = -(-n // CHUNK_SIZE)
    # Pad the last chunk by repeating its last splat so per-chunk min/max is a plain reshape.
    pad = np.concatenate([order, np.full(n_chunks * CHUNK_SIZE - n, order[-1], np.intp)])

    def chunked(a: np.ndarray) -> np.ndarray:
        return np.asarray(a, np.float64)[pad].reshape(n_chunks, CHUNK_SIZE, -1)

    pos = chunked(scene.positions)
    log_scale = chunked(np.log(np.maximum(scene.scales, 1e-30)))
    colour = chunked(sh_dc_to_rgb(scene.sh[:, 0]))
    p_lo, p_hi = pos.min(1, keepdims=True), pos.max(1, keepdims=True)
    s_lo = np.clip(log_scale.min(1, keepdims=True), -20, 20)
    s_hi = np.clip(log_scale.max(1, keepdims=True), -20, 20)
    c_lo, c_hi = colour.min(1, keepdims=True), colour.max(1, keepdims=True)

    def pack111011(t: np.ndarray) -> np.ndarray:
        t = t.reshape(-1, 3)[:n]
        return (_pack_unorm(t[:, 0], 11) << np.uint32(21)) | (_pack_unorm(t[:, 1], 10) << np.uint32(11)) \
            | _pack_unorm(t[:, 2], 11)

    t_col = _normalise_in_range(colour, c_lo, c_hi).reshape(-1, 3)[:n]
    alpha = np.asarray(scene.opacities, np.float64)[order]
    vertex = np.empty(n, [(name, "<u4") for name in _PACKED])
    vertex["packed_position"] = pack111011(_normalise_in_range(pos, p_lo, p_hi))
    vertex["packed_rotation"] = _pack_rotation(scene.rotations[order])
    vertex["packed_scale"] = pack111011(_normalise_in_range(log_scale, s_lo, s_hi))
    vertex["packed_color"] = ((_pack_unorm(t_col[:, 0], 8) << np.uint32(24)) | (_pack_unorm(t_col[:, 1], 8) <<
    np.uint32(16))
                              | (_pack_unorm(t_col[:, 2], 8) << np.uint32(8)) | _pack_unorm(alpha, 8))

    chunks = np.empty(n_chunks, [(name, "<f4") for name in _CHUNK_BASE + _CHUNK_COLOUR])
    for i, axis in enumerate("xyz"):
        chunks[f"min_{axis}"], chunks[f"max_{axis}"] = p_lo[:, 0, i], p_hi[:, 0, i]
        chunks[f"min_scale_{axis}"], chunks[f"max_scale_{axis}"] = s_lo[:, 0, i], s_hi[:, 0, i]
    for i, ch in enumerate("rgb"):
        chunks[f"min_{ch}"], chunks[f"max_{ch}"] = c_lo[:, 0, i], c_hi[:, 0, i]

    elements = [PlyElement.describe(chunks, "chunk"), PlyElement.describe(vertex, "vertex")]
    k = scene.sh.shape[1] - 1
    if k:
        rest = np.asarray(scene.sh[order, 1:], np.float64).transpose(0, 2, 1).reshape(n, 3 * k)
        sh = np.empty(n, [(f"f_rest_{i}", "u1") for i in range(3 * k)])
        q = np.clip(np.trunc((rest / 8.0 + 0.5) * 256.0), 0, 255).astype(np.uint8)
        for i in range(3 * k):
            sh[f"f_rest_{i}"] = q[:, i]
        elements.append(PlyElement.describe(sh, "sh"))
    PlyData(elements, text=False, byte_order="<", comments=["Generated by gs-ibl"]).write(path)
    return order
