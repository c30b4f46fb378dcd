"""PlayCanvas SOG, version 2: a ``meta.json`` and lossless WebP images, in a folder or a ``.sog`` zip.

Layout (as PlayCanvas splat-transform writes and reads it; one pixel per splat, row-major, images at least
``count`` pixels):
  means    two images, low and high bytes of 16-bit values in RGB; per axis t/65535 lerps between
           ``means.mins`` and ``means.maxs``, which bound the log-transformed position sign(x) * ln(|x| + 1)
  scales   RGB = indices into ``scales.codebook`` (256 log scales)
  quats    smallest three: RGB = the three other components of the unit quaternion (w, x, y, z) times sqrt 2,
           mapped [-1, 1] -> [0, 255]; A = 252 + index of the largest component (made positive); another tag
           means the identity rotation
  sh0      RGB = indices into ``sh0.codebook`` (f_dc values); A = sigmoid(opacity) * 255
  shN      (optional) ``bands`` 1-3 and ``count`` palette entries: labels image (16-bit index in R, G) into a
           centroids image 64 entries wide, (bands+1)^2 - 1 pixels per entry, whose RGB index ``shN.codebook``
Coordinates are those of 3DGS PLY data (no axis change). Version 1 (2024; per-channel ranges instead of
codebooks) is refused with advice.

Precision: positions 16 bits of the log-transformed range (finer near the origin); scales, colours and SH to
their 256-entry codebooks; opacity 8 bits; rotations 8 bits per component. ``write_sog`` writes SH degree 0
only (SOG's SH palette needs a k-means clustering we do not run); its codebooks hold 128 quantiles and 128 even
steps of each quantity's range, so no value moves by more than 1/254 of its range.
"""
from __future__ import annotations

import io
import json
import math
import os
import zipfile
from functools import partial

import numpy as np

from ..scene import SplatScene
from .checks import check_input, fail
from . import webp
from .repair import clamp_scales, new_counts, reported

_REEXPORT = "re-export it with SuperSplat or PlayCanvas splat-transform"
_fail = partial(fail, todo=_REEXPORT)
_ALPHA_EPS = 0.25 / 255.0  # keep 8-bit opacities inside (0, 1), as the other 8-bit readers do
_MAX_META = 64 << 20  # a meta.json is a few kB; more is not a SOG file
_MAX_ENTRY_RATIO = 64  # an image entry larger than this many bytes per splat is not a SOG image (zip bombs)
_SH_COEFFS = {1: 3, 2: 8, 3: 15}


class _Files:
    """The members of a SOG: a zip, or the folder holding meta.json."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.zip: zipfile.ZipFile | None = None
        if os.path.isdir(path):
            self.folder = path
        elif os.path.basename(path).lower() == "meta.json":
            self.folder = os.path.dirname(os.path.abspath(path))
        else:
            try:
                self.zip = zipfile.ZipFile(path)
            except (zipfile.BadZipFile, OSError, ValueError) as e:
                raise _fail(path, f"not a readable .sog zip ({e}): truncated or damaged") from None
            self.folder = ""

    def read(self, name: str, limit: int) -> bytes:
        # A folder's images sit beside meta.json: a path elsewhere (../, /) is refused rather than followed.
        if not isinstance(name, str) or not name or (self.zip is None and os.path.basename(name) != name):
            raise _fail(self.path, f"meta.json names the file {name!r}, which is not a plain file name")
        if self.zip is not None:
            try:
                info = self.zip.getinfo(name)
            except KeyError:
                raise _fail(self.path, f"the zip holds no '{name}' (it holds {', '.join(self.zip.namelist()[:8])})"
                            ) from None
            if info.file_size > limit:
                raise _fail(self.path, f"'{name}' unpacks to {info.file_size:,} bytes, more than a SOG image of this "
                                       "many splats can be: damaged")
            try:
                return self.zip.read(info)
            except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as e:
                raise _fail(self.path, f"'{name}' cannot be unpacked ({e}): truncated or damaged") from None
        full = os.path.join(self.folder, name)
        if not os.path.isfile(full):
            raise _fail(self.path, f"meta.json names '{name}' but {full} is missing",
                        todo="copy the whole SOG folder, or use the .sog file")
        if os.path.getsize(full) > limit:
            raise _fail(full, f"{os.path.getsize(full):,} bytes, more than a SOG image of this many splats can be")
        with open(full, "rb") as f:
            return f.read()

    def close(self) -> None:
        if self.zip is not None:
            self.zip.close()


def _numbers(path: str, meta: dict, key: str, field: str, length: int) -> np.ndarray:
    value = meta.get(key, {}).get(field) if isinstance(meta.get(key), dict) else None
    try:
        arr = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (length,):
        raise _fail(path, f"meta.json '{key}.{field}' must be {length} numbers, got {str(value)[:60]}")
    if not np.all(np.isfinite(arr)):
        raise _fail(path, f"meta.json '{key}.{field}' holds NaN or infinite values: damaged")
    return arr


def _files(path: str, meta: dict, key: str, count: int) -> list[str]:
    section = meta.get(key)
    files = section.get("files") if isinstance(section, dict) else None
    if not isinstance(files, list) or len(files) != count or not all(isinstance(f, str) for f in files):
        raise _fail(path, f"meta.json '{key}.files' must list {count} image file name(s), got {str(files)[:60]}")
    return files


def _image(path: str, src: _Files, name: str, n: int, what: str) -> np.ndarray:
    """The first n pixels (n, 4) of an image, refusing images smaller than n pixels."""
    data = src.read(name, 4096 + _MAX_ENTRY_RATIO * n)
    try:
        rgba = webp.decode(data)
    except webp.WebPUnavailable as e:
        raise fail(path, str(e)) from None
    except ValueError as e:
        raise _fail(path, f"'{name}' ({what}): {e}") from None
    h, w = rgba.shape[:2]
    if w * h < n:
        raise _fail(path, f"'{name}' ({what}) has {w}x{h} = {w * h:,} pixels for {n:,} splats: damaged")
    return rgba.reshape(-1, 4)[:n]


def read_sog(path: str | os.PathLike) -> SplatScene:
    """Decode a SOG (``.sog`` zip, a folder with meta.json, or the meta.json itself) into a SplatScene."""
    path = check_input(path)
    src = _Files(path)
    try:
        return _read(path, src)
    finally:
        src.close()


def _read(path: str, src: _Files) -> SplatScene:
    raw = src.read("meta.json", _MAX_META)
    try:
        meta = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise _fail(path, f"meta.json is not valid JSON ({e})") from None
    if not isinstance(meta, dict):
        raise _fail(path, "meta.json is not a JSON object")
    version = meta.get("version")
    if version is None:
        raise fail(path, "this is a version 1 SOG (2024), which this add-on does not read",
                   "convert it to SOG version 2 or PLY with a current PlayCanvas splat-transform")
    if version != 2:
        raise fail(path, f"SOG version {version!r}; this add-on reads version 2",
                   "convert it to SOG version 2 or PLY with PlayCanvas splat-transform")
    n = meta.get("count")
    if isinstance(n, bool) or not isinstance(n, int) or n <= 0:
        raise _fail(path, f"meta.json 'count' must be a whole number of splats above 0, got {n!r}")
    if n > 1 << 28:
        raise _fail(path, f"meta.json claims {n:,} splats, more than any SOG image can hold: damaged")
    mins = _numbers(path, meta, "means", "mins", 3)
    maxs = _numbers(path, meta, "means", "maxs", 3)
    scale_book = _numbers(path, meta, "scales", "codebook", 256)
    colour_book = _numbers(path, meta, "sh0", "codebook", 256)
    means_files = _files(path, meta, "means", 2)
    (scale_file,), (quat_file,), (sh0_file,) = (_files(path, meta, k, 1) for k in ("scales", "quats", "sh0"))
    sh_n = meta.get("shN")
    bands = 0
    if sh_n is not None:
        bands = sh_n.get("bands") if isinstance(sh_n, dict) else None
        if bands not in _SH_COEFFS:
            raise _fail(path, f"meta.json 'shN.bands' must be 1, 2 or 3, got {bands!r}")
        palette = sh_n.get("count")
        if isinstance(palette, bool) or not isinstance(palette, int) or not 0 < palette <= 65536:
            raise _fail(path, f"meta.json 'shN.count' must be 1 to 65536 palette entries, got {palette!r}")
        sh_book = _numbers(path, meta, "shN", "codebook", 256)
        sh_files = _files(path, meta, "shN", 2)
    counts = new_counts()

    lo = _image(path, src, means_files[0], n, "positions, low bytes")[:, :3].astype(np.uint32)
    hi = _image(path, src, means_files[1], n, "positions, high bytes")[:, :3].astype(np.uint32)
    t = (lo | (hi << 8)).astype(np.float64) / 65535.0
    span = np.where(maxs - mins == 0, 1.0, maxs - mins)  # as splat-transform: a flat axis decodes to mins
    v = mins + span * t
    positions = (np.sign(v) * np.expm1(np.abs(v))).astype(np.float32)

    s = _image(path, src, scale_file, n, "scales")
    scales = np.exp(scale_book[s[:, :3]]).astype(np.float32)
    if not np.all(np.isfinite(scales)):
        raise _fail(path, "scales.codebook overflows exp(): the values are not log scales")
    clamp_scales(scales, counts)

    q = _image(path, src, quat_file, n, "rotations")
    rotations = _unpack_quats(q, counts)

    c = _image(path, src, sh0_file, n, "colours and opacities")
    k = 1 + (_SH_COEFFS[bands] if bands else 0)
    sh = np.zeros((n, k, 3), np.float32)
    sh[:, 0] = colour_book[c[:, :3]]
    opacities = np.clip(c[:, 3].astype(np.float32) / 255.0, _ALPHA_EPS, 1 - _ALPHA_EPS)
    if bands:
        _read_sh(path, src, sh, sh_files, sh_book, bands, palette)
    return SplatScene(positions, scales, rotations, opacities, sh, source=path, repairs=reported(counts))


def _unpack_quats(q: np.ndarray, counts: dict[str, int]) -> np.ndarray:
    tag = q[:, 3].astype(np.intp)
    valid = (tag >= 252) & (tag <= 255)
    largest = np.where(valid, tag - 252, 0)
    others = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], np.intp)[largest]
    small = (q[:, :3].astype(np.float64) / 255.0 * 2.0 - 1.0) / math.sqrt(2.0)
    out = np.zeros((len(q), 4))
    rows = np.arange(len(q))[:, None]
    out[rows, others] = small
    out[rows[:, 0], largest] = np.sqrt(np.maximum(0.0, 1.0 - np.einsum("ij,ij->i", small, small)))
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    out[~valid] = (1.0, 0.0, 0.0, 0.0)
    counts["identity_rotations"] += int((~valid).sum())
    return out.astype(np.float32)


def _read_sh(path: str, src: _Files, sh: np.ndarray, files: list[str], book: np.ndarray, bands: int,
             palette: int) -> None:
    n, per = len(sh), _SH_COEFFS[bands]
    centroids = _image(path, src, files[0], min(palette, 65536) * per, "SH palette")
    labels = _image(path, src, files[1], n, "SH labels")
    label = labels[:, 0].astype(np.int64) | (labels[:, 1].astype(np.int64) << 8)
    # The palette image is 64 entries wide; _image flattened it row-major, so entry e's coefficient j sits at
    # pixel e * per + j (row e // 64, column (e % 64) * per + j).
    ok = label < palette
    idx = label[ok, None] * per + np.arange(per)[None, :]
    sh[ok, 1:] = book[centroids[idx][..., :3]]


# ---------------------------------------------------------------- writing


def _codebook(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """256 representative values and each value's nearest index: 128 quantiles (fine where values crowd) merged
    with 128 evenly spaced levels (so no value is further than 1/254 of the range from an entry)."""
    flat = values.astype(np.float64).ravel()
    book = np.sort(np.concatenate([np.quantile(flat, np.linspace(0.0, 1.0, 128)),
                                   np.linspace(flat.min(), flat.max(), 128)]))
    mids = (book[1:] + book[:-1]) / 2
    return book, np.searchsorted(mids, values.astype(np.float64)).astype(np.uint8)


def _square(n: int) -> tuple[int, int]:
    w = max(4, int(math.ceil(math.sqrt(n) / 4.0)) * 4)
    return w, -(-n // w)


def _pack_image(rgba: np.ndarray, n: int) -> bytes:
    w, h = _square(n)
    full = np.zeros((w * h, 4), np.uint8)
    full[:, 3] = 255
    full[:n] = rgba
    return webp.encode_lossless(full.reshape(h, w, 4))


def write_sog(path: str | os.PathLike, scene: SplatScene) -> None:
    """Write ``scene`` as a ``.sog`` zip (SH degree 0: see the module docstring)."""
    path = os.fspath(path)
    n = scene.count
    if n == 0:
        raise ValueError(f"{path}: the scene has no splats to write")
    pos = scene.positions.astype(np.float64)
    v = np.sign(pos) * np.log1p(np.abs(pos))
    mins, maxs = v.min(0), v.max(0)
    span = np.where(maxs - mins == 0, 1.0, maxs - mins)
    q16 = np.clip(np.round((v - mins) / span * 65535.0), 0, 65535).astype(np.uint32)
    images = {}
    alpha = np.full((n, 1), 255, np.uint8)
    images["means_l.webp"] = np.concatenate([(q16 & 0xFF).astype(np.uint8), alpha], 1)
    images["means_u.webp"] = np.concatenate([(q16 >> 8).astype(np.uint8), alpha], 1)
    scale_book, scale_idx = _codebook(np.log(scene.scales.astype(np.float64)))
    images["scales.webp"] = np.concatenate([scale_idx, alpha], 1)
    images["quats.webp"] = _pack_quats(scene.rotations)
    colour_book, colour_idx = _codebook(scene.sh[:, 0])
    opacity = np.clip(np.round(scene.opacities.astype(np.float64) * 255.0), 0, 255).astype(np.uint8)
    images["sh0.webp"] = np.concatenate([colour_idx, opacity[:, None]], 1)
    meta = {"version": 2, "asset": {"generator": "gs-ibl"}, "count": n,
            "means": {"mins": mins.tolist(), "maxs": maxs.tolist(), "files": ["means_l.webp", "means_u.webp"]},
            "scales": {"codebook": scale_book.tolist(), "files": ["scales.webp"]},
            "quats": {"files": ["quats.webp"]},
            "sh0": {"codebook": colour_book.tolist(), "files": ["sh0.webp"]}}
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as z:  # WebP is compressed already
        z.writestr("meta.json", json.dumps(meta))
        for name, rgba in images.items():
            z.writestr(name, _pack_image(rgba, n))
    with open(path, "wb") as f:
        f.write(buffer.getvalue())


def _pack_quats(rotations: np.ndarray) -> np.ndarray:
    q = rotations.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    largest = np.argmax(np.abs(q), 1)
    rows = np.arange(len(q))
    q *= np.where(q[rows, largest] < 0, -1.0, 1.0)[:, None]
    others = q[rows[:, None], np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[largest]]
    b = np.clip(np.round((others * math.sqrt(2.0) * 0.5 + 0.5) * 255.0), 0, 255).astype(np.uint8)
    return np.concatenate([b, (252 + largest).astype(np.uint8)[:, None]], 1)
