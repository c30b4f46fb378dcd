"""``.ksplat``, the format of mkkellogg's GaussianSplats3D viewer (read only).

Layout (little-endian; as GaussianSplats3D writes it and PlayCanvas splat-transform reads it):
  main header, 4096 bytes: u8 major version (0), u8 minor (>= 1), u32 section count at 4, u32 splat count at 16,
  u16 compression mode at 20 (0: float32, 1: float16, 2: float16 with 8-bit SH), f32 SH range at 36/40 (mode 2;
  0 means -1.5/+1.5);
  section headers, 1024 bytes each: u32 splats at 0, u32 capacity at 4, u32 bucket capacity at 8, u32 buckets at
  12, f32 block size at 16, u16 bytes per bucket at 20, u32 quantisation range at 24 (0: 32767), u32 full
  buckets at 32, u32 partial buckets at 36, u16 SH degree at 40;
  per section: u32 sizes of the partial buckets, the buckets' f32 centres, then ``capacity`` records of
  position (3 x f32, or 3 x u16 offsets from the bucket centre in units of block size / 2 / range), scale
  (linear, 3 x f32 or f16), rotation (w x y z, f32 or f16), RGBA8 (colour 0.5 + SH_C0 * f_dc, A = opacity),
  SH rest (f32, f16 or u8 over the SH range) in the order degree 1 (r g b, 3 each) then degree 2 (5 each).
Coordinates are those of 3DGS PLY data. Precision: mode 0 keeps float32; modes 1-2 keep positions to
block size / 65534, scales and rotations as float16, colour and opacity 8 bits, SH as float16 or 8 bits.
"""
from __future__ import annotations

import os
import struct
from functools import partial

import numpy as np

from ..scene import SplatScene, rgb_to_sh_dc
from .checks import check_input, fail
from .repair import clamp_scales, new_counts, normalise_quaternions, reported

MAIN_HEADER = 4096
SECTION_HEADER = 1024
_MODES = {0: ("<f4", "<f4", "<f4"), 1: ("<u2", "<f2", "<f2"), 2: ("<u2", "<f2", "u1")}  # centre, scale/rot, SH
_SH_REST = {0: 0, 1: 9, 2: 24, 3: 45}
_ALPHA_EPS = 0.25 / 255.0
_fail = partial(fail, todo="re-export it from GaussianSplats3D, or export a 3DGS PLY instead")


def _record(mode: int, degree: int) -> np.dtype:
    centre, half, sh = _MODES[mode]
    fields = [("centre", centre, 3), ("scale", half if mode else "<f4", 3), ("rotation", half if mode else "<f4", 4),
              ("rgba", "u1", 4)]
    if _SH_REST[degree]:
        fields.append(("sh", sh, _SH_REST[degree]))
    return np.dtype(fields)


def _sh_columns(degree: int) -> np.ndarray:
    """Where stored SH value i goes in 3DGS's channel-major f_rest order (degree 1 first, channel-major per band)."""
    per = _SH_REST[degree] // 3
    cols = []
    for i in range(_SH_REST[degree]):
        if i < 9:
            channel, coeff = i // 3, i % 3
        elif i < 24:
            channel, coeff = (i - 9) // 5, (i - 9) % 5 + 3
        else:
            channel, coeff = (i - 24) // 7, (i - 24) % 7 + 8
        cols.append(channel * per + coeff)
    return np.array(cols, np.intp)


def read_ksplat(path: str | os.PathLike) -> SplatScene:
    """Decode a .ksplat file into an activated SplatScene."""
    path = check_input(path)
    size = os.path.getsize(path)
    if size < MAIN_HEADER:
        raise _fail(path, f"only {size:,} bytes; a .ksplat header alone is {MAIN_HEADER}: truncated or not .ksplat")
    with open(path, "rb") as f:
        data = f.read()
    major, minor = data[0], data[1]
    sections, n = struct.unpack_from("<I", data, 4)[0], struct.unpack_from("<I", data, 16)[0]
    mode = struct.unpack_from("<H", data, 20)[0]
    sh_lo, sh_hi = struct.unpack_from("<ff", data, 36)
    if major != 0 or minor < 1:
        raise _fail(path, f"version {major}.{minor}; .ksplat files are version 0.1 or later 0.x: not a .ksplat file")
    if mode not in _MODES:
        raise _fail(path, f"compression mode {mode}; .ksplat has modes 0, 1 and 2: damaged")
    if n == 0:
        raise _fail(path, "the header says the file holds 0 splats")
    if MAIN_HEADER + sections * SECTION_HEADER > size:
        raise _fail(path, f"the header announces {sections:,} sections, whose headers alone overrun the "
                          f"{size:,}-byte file: truncated or damaged")
    if not (np.isfinite(sh_lo) and np.isfinite(sh_hi)):
        raise _fail(path, "the SH range in the header is not finite: damaged")
    sh_lo, sh_hi = (sh_lo or -1.5), (sh_hi or 1.5)
    heads = [struct.unpack_from("<IIIIfHxxIxxxxIIH", data, MAIN_HEADER + i * SECTION_HEADER) for i in range(sections)]
    degree = max([h[9] for h in heads if h[0]] or [0])
    if degree not in _SH_REST:
        raise _fail(path, f"SH degree {degree} in a section header; .ksplat stores 0 to 3: damaged")
    k = (degree + 1) ** 2
    positions = np.empty((n, 3), np.float32)
    scales = np.empty((n, 3), np.float32)
    rotations = np.empty((n, 4), np.float32)
    rgba = np.empty((n, 4), np.uint8)
    sh = np.zeros((n, k, 3), np.float32)
    at, m = MAIN_HEADER + sections * SECTION_HEADER, 0
    for s, (count, capacity, bucket_cap, buckets, block, bucket_bytes, qrange, full, partial_n, sdeg) in \
            enumerate(heads):
        if sdeg not in _SH_REST:
            raise _fail(path, f"section {s} has SH degree {sdeg}; .ksplat stores 0 to 3: damaged")
        rec = _record(mode, sdeg)
        meta = bucket_bytes * buckets + 4 * partial_n
        end = at + meta + rec.itemsize * capacity
        if count > capacity or m + count > n or end > size:
            raise _fail(path, f"section {s} ({count:,} splats of {capacity:,}, {buckets:,} buckets) does not fit: the "
                              f"file ends at byte {size:,} or the counts disagree with the header's {n:,}: damaged")
        if count:
            rows = np.frombuffer(data, rec, count, at + meta)
            if mode:
                qrange = qrange or 32767
                if buckets == 0 or bucket_cap == 0 or not np.isfinite(block):
                    raise _fail(path, f"section {s} has quantised positions but no buckets: damaged")
                centres = np.frombuffer(data, "<f4", 3 * buckets, at + 4 * partial_n).reshape(buckets, 3)
                sizes = np.frombuffer(data, "<u4", partial_n, at).astype(np.int64)
                if sizes.sum() > count:  # before np.repeat: a damaged count must not claim gigabytes
                    raise _fail(path, f"section {s}: its bucket sizes add up to {int(sizes.sum()):,}, more than "
                                      f"its {count:,} splats: damaged")
                fulls = min(full * bucket_cap, count)
                bucket = np.concatenate([np.arange(fulls) // bucket_cap,
                                         np.repeat(np.arange(full, full + partial_n), sizes)])[:count]
                if len(bucket) < count or (bucket >= buckets).any():
                    raise _fail(path, f"section {s}: its bucket sizes do not cover its {count:,} splats: damaged")
                step = np.float64(block) / 2.0 / qrange
                pos = (rows["centre"].astype(np.float64) - qrange) * step + centres[bucket]
            else:
                pos = rows["centre"]
            positions[m:m + count] = pos
            scales[m:m + count] = rows["scale"]
            rotations[m:m + count] = rows["rotation"]
            rgba[m:m + count] = rows["rgba"]
            if _SH_REST[sdeg]:
                vals = rows["sh"].astype(np.float32)
                if mode == 2:
                    vals = np.float32(sh_lo) + vals * np.float32((sh_hi - sh_lo) / 255.0)
                rest = np.zeros((count, 3 * (k - 1)), np.float32)
                cols = _sh_columns(sdeg)
                per_in, per_out = _SH_REST[sdeg] // 3, k - 1
                # re-index the section's own channel-major columns into the file-wide degree
                rest[:, (cols // per_in) * per_out + cols % per_in] = vals
                sh[m:m + count, 1:] = rest.reshape(count, 3, k - 1).transpose(0, 2, 1)
        m += count
        at = end
    if m != n:
        raise _fail(path, f"the sections hold {m:,} splats but the header says {n:,}: damaged")
    counts = new_counts()
    finite = np.isfinite(positions).all(1) & np.isfinite(scales).all(1) & np.isfinite(rotations).all(1) \
        & np.isfinite(sh).all((1, 2))
    if not finite.any():
        raise _fail(path, f"all {n} splats have non-finite values: damaged")
    if not finite.all():
        counts["dropped_nonfinite"] = int(n - finite.sum())
        positions, scales, rotations, rgba, sh = (a[finite] for a in (positions, scales, rotations, rgba, sh))
    if (scales < 0).any():
        raise _fail(path, f"{int((scales < 0).any(1).sum())} splats have negative scales; .ksplat stores linear "
                          "scales, which are never negative: damaged")
    scales = np.ascontiguousarray(scales)
    clamp_scales(scales, counts)
    rotations = normalise_quaternions(rotations, counts)
    sh[:, 0] = rgb_to_sh_dc(rgba[:, :3].astype(np.float32) / 255.0)
    opacities = np.clip(rgba[:, 3].astype(np.float32) / 255.0, _ALPHA_EPS, 1 - _ALPHA_EPS)
    return SplatScene(positions, scales, rotations, opacities, sh, source=path, repairs=reported(counts))


def write_ksplat(path: str | os.PathLike, scene: SplatScene, mode: int = 0) -> None:
    """Write ``scene`` as a one-section .ksplat (mode 0: float32; 1: float16 with quantised positions), SH to
    degree 2 at most (GaussianSplats3D stops there). Used by the tests, which check it against splat-transform's
    reader, and by ``convert``."""
    path = os.fspath(path)
    n = scene.count
    degree = min(scene.sh_degree, 2)
    rec = np.zeros(n, _record(mode, degree))
    bucket_cap, block, qrange = 256, 0.0, 32767
    header_extra = b""
    buckets, full = 0, 0
    if mode:
        pos = scene.positions.astype(np.float64)
        buckets = -(-n // bucket_cap)
        full = buckets
        pad = np.concatenate([pos, np.repeat(pos[-1:], buckets * bucket_cap - n, 0)]).reshape(buckets, bucket_cap, 3)
        centres = (pad.min(1) + pad.max(1)) / 2
        block = float(2.0 * np.abs(pad - centres[:, None]).max() * (1 + 1e-6) or 1.0)
        step = block / 2.0 / qrange
        offsets = pos - np.repeat(centres, bucket_cap, 0)[:n]
        rec["centre"] = np.clip(np.round(offsets / step + qrange), 0, 65535)
        header_extra = centres.astype("<f4").tobytes()
        full = buckets
    else:
        rec["centre"] = scene.positions
    rec["scale"] = scene.scales
    rec["rotation"] = scene.rotations
    rgb = np.clip(0.5 + 0.28209479177387814 * scene.sh[:, 0].astype(np.float64), 0, 1)
    rec["rgba"] = np.round(np.concatenate([rgb, scene.opacities[:, None]], 1) * 255)
    if degree:
        k = (degree + 1) ** 2
        rest = scene.sh[:, 1:k].transpose(0, 2, 1).reshape(n, 3 * (k - 1))  # channel-major, like f_rest
        cols = _sh_columns(degree)
        rec["sh"] = rest[:, cols]
    main = bytearray(MAIN_HEADER)
    main[0], main[1] = 0, 1
    struct.pack_into("<IIIIH", main, 4, 1, 1, n, n, mode)
    section = bytearray(SECTION_HEADER)
    struct.pack_into("<IIIIfHxxIxxxxIIH", section, 0, n, n, bucket_cap, buckets, block,
                     12 if mode else 0, qrange, full, 0, degree)
    with open(path, "wb") as f:
        f.write(bytes(main) + bytes(section) + header_extra + rec.tobytes())
