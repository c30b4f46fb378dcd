"""The standard 3DGS PLY layout (as written by the INRIA reference trainer and most tools): read and write.

Layout: one ``vertex`` element with float properties ``x y z``, optional ``nx ny nz`` (ignored),
``f_dc_0..2``, ``f_rest_0..R-1`` with R in {0, 9, 24, 45} (SH degree 0-3), ``opacity``, ``scale_0..2``,
``rot_0..3``. Extra properties are ignored; any numeric property type is accepted (cast to float32).
Binary little/big-endian files are read through plyfile's header parser, then in chunks into one reused buffer
(so a file of any size costs little more than the resulting arrays); a file whose properties share one type (the
usual all-float32 one) has each chunk's columns gathered in one pass. ASCII files whose first element is
``vertex`` (other elements, e.g. faces, may follow) are parsed by numpy's C parser a block at a time
(``_rows_ascii``: 4-5x plyfile's pure-Python reader on 1M splats, values identical; docs/benchmarks.md); other
ASCII layouts by plyfile.

f_rest is stored channel-major: ``f_rest_{c * (K-1) + (k-1)}`` is coefficient k of channel c, where K is the
number of SH coefficients per channel; ``SplatScene.sh[:, k, c]`` holds it and ``sh[:, 0]`` is f_dc.

Activation (what ``SplatScene`` holds): opacity = sigmoid(raw), scale = exp(raw), rotation = the quaternion
``(rot_0, rot_1, rot_2, rot_3) = (w, x, y, z)`` divided by its length (computed in float64, rounded to float32).

Errors (one ``SplatFormatError`` naming the file, the field and what to do; nothing is returned):
  missing file; unreadable header (not a PLY); no ``vertex`` element; a mesh / point-cloud PLY (a ``face``
  element, or none of the splat properties) ; missing or misspelt properties (the close name found is suggested);
  a list property where a number is expected; an f_rest count other than 0, 9, 24, 45 or gaps in its numbering;
  a truncated file (fewer bytes or lines than the header promises); zero splats; every splat non-finite.
  Element counts (negative, or more than the file's size can hold) are checked against the file size straight
  after the header (``check_counts``), before any array is allocated.
Repairs (formats/repair.py; done silently to the data, counted in ``scene.repairs``, a key only when its count > 0):
  ``dropped_nonfinite``  splats with NaN/inf in any field used (or whose exp(scale) overflows float32) are dropped;
  ``clamped_scales``     splats with a scale below ``MIN_SCALE`` (exp(raw) zero or subnormal, where 1/scale^2 would
                         overflow float32 in a renderer) get that axis clamped to ``MIN_SCALE``;
  ``identity_rotations`` splats whose quaternion is exactly zero get the identity rotation.
Unnormalised quaternions are not a repair: 3DGS always stores them unnormalised, and normalising is the activation.
A quaternion that is already unit to float32 precision is kept bit-for-bit, and ``write_ply`` picks, per value,
the float32 raw opacity/scale whose activation gives back exactly the scene's float32 value where one exists, so
``read_ply(write_ply(read_ply(f)))`` equals ``read_ply(f)`` bit-for-bit.
"""
from __future__ import annotations

import difflib
import os
import re
import warnings
from dataclasses import dataclass

import numpy as np
from plyfile import PlyData, PlyElement, PlyListProperty, PlyParseError

from ..scene import SplatScene
from .checks import check_input, fail
from .repair import clamp_scales, new_counts, normalise_quaternions, reported

CHUNK_ROWS = 1 << 14  # splats converted per step: a few MB, so a chunk's temporaries stay in the CPU's cache
ASCII_BLOCK = 32 << 20  # bytes of ASCII PLY text parsed per step
F_REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}  # f_rest properties -> SH degree

_SPLAT_ONLY = ["f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
               "rot_0", "rot_1", "rot_2", "rot_3"]
_REQUIRED = ["x", "y", "z"] + _SPLAT_ONLY
_F_REST = re.compile(r"f_rest_(\d+)$")
_ADVICE = ("a 3DGS splat PLY needs the vertex properties x y z f_dc_0..2 opacity scale_0..2 rot_0..3 "
           "(and optionally f_rest_*); re-export it from your 3DGS trainer or editor in the standard layout")


@dataclass
class _Layout:
    """Where each activated quantity comes from: the property names in the order of a raw row."""
    names: list[str]
    k: int  # SH coefficients per channel

    @classmethod
    def standard(cls, degree: int) -> "_Layout":
        k = (degree + 1) ** 2
        rest = [f"f_rest_{i}" for i in range(3 * (k - 1))]
        return cls(["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", *rest, "opacity",
                    "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"], k)

    @property
    def sh_end(self) -> int:
        return 6 + 3 * (self.k - 1)


# Activations, in float64 then rounded once to float32: the writer inverts exactly these functions.
def _sigmoid32(raw: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        return (1.0 / (1.0 + np.exp(-np.asarray(raw, np.float64)))).astype(np.float32)


def _exp32(raw: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        return np.exp(np.asarray(raw, np.float64)).astype(np.float32)


def _check_header(path: str, ply: PlyData) -> tuple[PlyElement, _Layout]:
    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise fail(path, f"no 'vertex' element (elements found: {', '.join(names) or 'none'}); {_ADVICE}")
    vertex = ply["vertex"]
    props = [p.name for p in vertex.properties]
    missing = [n for n in _REQUIRED if n not in props]
    if missing:
        looks_splat = any(difflib.get_close_matches(n, props, n=1, cutoff=0.8) for n in _SPLAT_ONLY)
        if "face" in names or not looks_splat:
            why = "it has a 'face' element" if "face" in names else f"its vertices have only {', '.join(props)}"
            raise fail(path, f"this is a mesh or point-cloud PLY, not a 3DGS splat file ({why}; no "
                             f"{', '.join(missing)}). Import it with File > Import > Stanford PLY instead, or "
                             f"choose the splat PLY your 3DGS trainer wrote (e.g. point_cloud.ply)")
        unused = [p for p in props if p not in _REQUIRED]
        parts = []
        for n in missing:
            close = difflib.get_close_matches(n, unused, n=1, cutoff=0.6)
            parts.append(f"'{n}'" + (f" (found '{close[0]}': a misspelling? rename it to '{n}')" if close else ""))
        raise fail(path, f"vertex property {', '.join(parts)} missing; {_ADVICE}")

    rest = sorted(int(m.group(1)) for p in props if (m := _F_REST.match(p)))
    if len(rest) not in F_REST_COUNTS:
        raise fail(path, f"{len(rest)} f_rest_* properties; the standard layout has 0, 9, 24 or 45 "
                         f"(SH degree 0-3). Re-export the file with SH degree 0-3")
    if rest != list(range(len(rest))):
        gap = sorted(set(range(len(rest))) - set(rest))
        raise fail(path, f"f_rest properties are not numbered 0..{len(rest) - 1} (f_rest_{gap[0]} is missing); "
                         f"the file is not in the standard layout: re-export it")
    layout = _Layout.standard(F_REST_COUNTS[len(rest)])
    for p in vertex.properties:
        if p.name in layout.names and isinstance(p, PlyListProperty):
            raise fail(path, f"vertex property '{p.name}' is a list, expected one number per splat; "
                             f"re-export the file in the standard 3DGS layout")
    if vertex.count == 0:
        raise fail(path, "the vertex element holds 0 splats: nothing to import. Check the export")
    return vertex, layout


def _min_row_bytes(element: PlyElement, text: bool, byte_order: str) -> int:
    """The fewest bytes one row of ``element`` can take: a list counts only its length field; in ASCII a value
    takes at least one character and one separator."""
    if text:
        return 2 * len(element.properties)
    total = 0
    for p in element.properties:
        if isinstance(p, PlyListProperty):
            total += np.dtype(p.len_dtype).itemsize
        else:
            total += np.dtype(p.val_dtype).itemsize
    return total


def check_counts(path: str, ply: PlyData, offset: int) -> None:
    """Refuse negative element counts, and counts the bytes after the header cannot hold, before any allocation."""
    have = os.path.getsize(path) - offset
    need = 0
    for element in ply.elements:
        if element.count < 0:
            raise fail(path, f"the header gives element '{element.name}' a negative count ({element.count}): "
                             "the file is damaged", "export it again")
        need += element.count * _min_row_bytes(element, ply.text, ply.byte_order)
        if need > have:
            rows = f"{element.count} splats" if element.name == "vertex" else f"{element.count} '{element.name}' rows"
            raise fail(path, f"the header promises {rows}, at least {need:,} bytes, but only {have:,} bytes follow "
                             "it: the file is truncated or its header is damaged",
                       "get the file again or export it again")


def _uniform_dtype(vertex: PlyElement, byte_order: str) -> np.dtype | None:
    """The one scalar type of every vertex property (the usual all-float32 file), else None."""
    types = {p.val_dtype for p in vertex.properties if not isinstance(p, PlyListProperty)}
    if len(types) != 1 or len(vertex.properties) != len(vertex.dtype(byte_order)):
        return None
    return np.dtype(byte_order + types.pop())


def _rows_binary(path: str, ply: PlyData, vertex: PlyElement, offset: int):
    """Yield the vertex rows chunk by chunk: (rows, properties) arrays where every property has one type (so the
    columns are gathered in one pass, not one strided pass per property), else structured arrays."""
    dtype = vertex.dtype(ply.byte_order)
    first = ply.elements[0].name == "vertex" and not any(isinstance(p, PlyListProperty) for p in vertex.properties)
    if not first:
        # Rare layouts (vertex after a variable-size element): let plyfile parse everything.
        data = _read_all(path, mmap=True)["vertex"].data
        for i in range(0, len(data), CHUNK_ROWS):
            yield data[i:i + CHUNK_ROWS]
        return
    need = vertex.count * dtype.itemsize
    have = os.path.getsize(path) - offset
    if have < need:
        raise fail(path, f"the file is truncated: the header promises {vertex.count} splats ({need} bytes) but only "
                         f"{have} bytes follow ({have // dtype.itemsize} whole splats). The download or copy was "
                         f"probably cut off: get the file again")
    plain = _uniform_dtype(vertex, ply.byte_order)
    # One reused buffer filled by readinto: resident memory stays one chunk whatever the file size, and a copy from
    # the page cache costs less than faulting in a fresh memory map per chunk.
    buf = np.empty(min(CHUNK_ROWS, vertex.count) * dtype.itemsize, np.uint8)
    with open(path, "rb") as f:
        f.seek(offset)
        for i in range(0, vertex.count, CHUNK_ROWS):
            rows = min(CHUNK_ROWS, vertex.count - i)
            view = buf[:rows * dtype.itemsize]
            if f.readinto(view) != view.size:
                raise fail(path, f"the file is truncated: splat {i} onwards could not be read; get the file again")
            yield view.view(plain).reshape(rows, -1) if plain is not None else view.view(dtype)


def _ascii_fast(ply: PlyData, vertex: PlyElement) -> bool:
    """The vertex rows come first and have a fixed number of values (elements after them, e.g. faces, are fine)."""
    return ply.elements[0] is vertex and not any(isinstance(p, PlyListProperty) for p in vertex.properties)


def _parse_lines(path: str, text: bytes, width: int, first_line: int, want: int) -> np.ndarray:
    """The slow, exact parse of a block the fast one could not take: blank lines skipped, the first line that
    does not hold ``width`` numbers named."""
    rows = []
    for i, line in enumerate(text.splitlines()):
        words = line.split()
        if not words:
            continue
        try:
            row = [float(w) for w in words]
        except ValueError:
            row = None
        if row is None or len(row) != width:
            raise fail(path, f"the PLY data cannot be parsed: line {first_line + i + 1} after the header does not "
                             f"hold {width} numbers (a word, a missing or an extra value); re-export the file")
        rows.append(row)
        if len(rows) == want:
            break
    return np.array(rows, np.float64).reshape(-1, width)


def _parse_block(text: bytes, width: int, most: int) -> np.ndarray | None:
    """The rows of a block of whole lines of numbers as (rows, width) float32, or None where it holds anything else
    (a word, a byte that is not ASCII, a number of values that is not a whole number of rows) or more than ``most``
    rows (other elements' lines after the vertices, which the caller cuts off).

    One call of numpy's C parser for the whole block: each value is parsed to double and rounded to float32, as
    plyfile's ``np.float32(word)`` does, so the values are identical. (np.loadtxt's C reader and splitting the bytes
    were measured slower.) Lines are not counted here (that is a pass over the block of its own): blank lines change
    no value, and a line short of a value makes the total no whole number of rows."""
    with warnings.catch_warnings():
        # numpy 1.x warns and returns what it read where 2.x raises ValueError: both mean "not only numbers"
        warnings.simplefilter("error", DeprecationWarning)
        try:
            values = np.fromstring(text, dtype=np.float32, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    if values.size % width or values.size > most * width:
        return None
    return values.reshape(-1, width)


def _rows_ascii(path: str, vertex: PlyElement, offset: int):
    """Yield the vertex rows of an ASCII PLY whose first element is vertex, parsed by numpy a block of whole lines
    at a time (plyfile parses each value in Python: about 20x slower). Each block is read once and parsed as it is:
    no decoding, no joining of blocks. The block where the vertices end is cut after their last line (other
    elements, e.g. faces, follow), and a block the fast parse refuses is read line by line, naming a bad line."""
    width, done = len(vertex.properties), 0
    with open(path, "rb") as f:
        f.seek(offset)
        while done < vertex.count:
            start = f.tell()
            text = f.read(ASCII_BLOCK)
            if not text:
                break
            if not text.endswith(b"\n"):
                text += f.readline()  # whole lines only (the file's last line may lack its line end)
            want = vertex.count - done
            rows = _parse_block(text, width, want)
            if rows is None:
                ends = np.flatnonzero(np.frombuffer(text, np.uint8) == ord("\n"))
                if len(ends) >= want and ends[want - 1] + 1 < len(text):  # the vertices end in this block
                    text = text[:ends[want - 1] + 1]
                    f.seek(start + len(text))
                    rows = _parse_block(text, width, want)
                if rows is None:  # blank lines or bad input
                    rows = _parse_lines(path, text, width, _lines_before(path, offset, start), want)
            done += len(rows)
            for i in range(0, len(rows), CHUNK_ROWS):
                yield rows[i:i + CHUNK_ROWS]
    if done < vertex.count:
        raise fail(path, f"the file is truncated: the header promises {vertex.count} splats but only {done} lines "
                         "of them follow. The download or copy was probably cut off: get the file again")


def _lines_before(path: str, offset: int, start: int) -> int:
    """Lines between the header's end and byte ``start``: counted only where a message needs a line number."""
    lines = 0
    with open(path, "rb") as f:
        f.seek(offset)
        while f.tell() < start:
            lines += f.read(min(ASCII_BLOCK, start - f.tell())).count(b"\n")
    return lines


def parse_header(path: str, check_sizes: bool = True) -> tuple[PlyData, int]:
    """plyfile's header parser on its own (so a bad layout is refused before any data is read), with the element
    counts checked against the file size unless ``check_sizes`` is False (the caller then calls ``check_counts``
    itself, after the checks whose messages say more); returns the header and the byte offset of the data."""
    try:
        with open(path, "rb") as f:
            ply = PlyData._parse_header(f)
            offset = f.tell()
    except (PlyParseError, UnicodeDecodeError, ValueError) as e:
        raise fail(path, f"not a readable PLY file (header: {e})", "choose a 3DGS .ply file") from None
    if check_sizes:
        check_counts(path, ply, offset)
    return ply, offset


def _read_all(path: str, mmap: bool) -> PlyData:
    try:
        return PlyData.read(path, mmap=mmap)
    except PlyParseError as e:
        if "early end-of-file" in str(e):
            raise fail(path, f"the file is truncated ({e}): the download or copy was probably cut off; "
                             f"get the file again") from None
        raise fail(path, f"the PLY data cannot be parsed ({e}); re-export the file") from None
    except (ValueError, UnicodeDecodeError) as e:  # e.g. a word where an ASCII PLY needs a number
        raise fail(path, f"the PLY data cannot be parsed ({e}); re-export the file") from None


def read_ply(path: str | os.PathLike) -> SplatScene:
    """Read a standard 3DGS PLY into an activated SplatScene (see the module docstring for errors and repairs)."""
    path = check_input(path)
    ply, offset = parse_header(path, check_sizes=False)
    if any(e.count < 0 for e in ply.elements):
        check_counts(path, ply, offset)  # a negative count: say so before the layout checks trip over it
    vertex, layout = _check_header(path, ply)  # a wrong layout says more than a wrong size: checked first
    check_counts(path, ply, offset)  # before any allocation
    if ply.text and _ascii_fast(ply, vertex):
        chunks = _rows_ascii(path, vertex, offset)
    elif ply.text:
        data = _read_all(path, mmap=False)["vertex"].data
        chunks = (data[i:i + CHUNK_ROWS] for i in range(0, len(data), CHUNK_ROWS))
    else:
        chunks = _rows_binary(path, ply, vertex, offset)
    props = [p.name for p in vertex.properties]
    return _activate(path, chunks, vertex.count, layout, [props.index(name) for name in layout.names])


def _activate(path: str, chunks, n: int, layout: _Layout, columns: list[int]) -> SplatScene:
    """``chunks`` yields (rows, file properties) arrays, whose ``columns`` are the layout's names, or arrays read by
    property name (structured)."""
    k = layout.k
    pos = np.empty((n, 3), np.float32)
    sh = np.empty((n, k, 3), np.float32)
    opa = np.empty((n,), np.float32)
    scl = np.empty((n, 3), np.float32)
    rot = np.empty((n, 4), np.float32)
    counts = new_counts()
    m = 0  # rows kept so far: dropped splats are compacted away as we go, never copied twice
    e = layout.sh_end
    for rows in chunks:
        if isinstance(rows, np.ndarray) and rows.ndim == 2:
            raw = rows[:, columns]  # one gather of every column, not a strided pass per column
            if raw.dtype != np.float32:
                raw = raw.astype(np.float32)
        else:
            raw = np.empty((len(rows), len(layout.names)), np.float32)
            for j, name in enumerate(layout.names):
                raw[:, j] = rows[name]
        s = _exp32(raw[:, e + 1:e + 4])
        keep = np.isfinite(raw).all(1) & np.isfinite(s).all(1)
        c = int(keep.sum())
        counts["dropped_nonfinite"] += len(raw) - c
        if c < len(raw):  # the usual file drops nothing: no compacting copy then
            raw, s = raw[keep], s[keep]

        pos[m:m + c] = raw[:, 0:3]
        sh[m:m + c, 0] = raw[:, 3:6]
        # channel-major f_rest: column 6 + ch*(k-1) + (i-1) -> sh[:, i, ch]
        sh[m:m + c, 1:] = raw[:, 6:e].reshape(c, 3, k - 1).transpose(0, 2, 1)
        opa[m:m + c] = _sigmoid32(raw[:, e])
        clamp_scales(s, counts)
        scl[m:m + c] = s
        rot[m:m + c] = normalise_quaternions(raw[:, e + 4:e + 8], counts)
        m += c
    if m == 0:
        raise fail(path, f"all {n} splats have NaN or infinite values; the file is damaged: re-export it")
    repairs = reported(counts)
    # Views of the first m rows: when splats were dropped the tail is unused, which is cheaper than copying.
    return SplatScene(pos[:m], scl[:m], rot[:m], opa[:m], sh[:m], source=path, repairs=repairs)


def _invert_exactly(forward, y: np.ndarray, guess: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """float32 raw values r with forward(r) == y where such r lies within 3 ulp of the float64 inverse ``guess``."""
    with np.errstate(invalid="ignore"):
        r0 = np.clip(guess, lo, hi).astype(np.float32)
    best = r0.copy()
    found = forward(r0) == y
    for direction in (np.float32(np.inf), np.float32(-np.inf)):
        r = r0
        for _ in range(3):
            if found.all():
                return best
            r = np.nextafter(r, direction)
            hit = ~found & (forward(r) == y)
            best[hit] = r[hit]
            found |= hit
    return best


def write_ply(path: str | os.PathLike, scene: SplatScene, ascii: bool = False, byte_order: str = "<",
              comments: tuple[str, ...] = ()) -> None:
    """Write ``scene`` in the standard 3DGS layout (raw values: logit opacity, log scale; normals written as 0),
    with ``comments`` in the header after ours (e.g. the axes declaration of formats/axes.py). A scene whose
    colour space is not what undeclared files are taken to hold (linear: synthetic scenes) declares it
    (formats/colour_space.py), so reading the file back applies the same colour rule.

    ``read_ply`` of the result gives back the scene's positions, SH and unit quaternions bit-for-bit, and opacities
    and scales bit-for-bit wherever the float32 value is reachable as the activation of a float32 raw value (always
    for a scene that was itself read from a PLY; otherwise to within one float32 rounding).
    """
    path = os.fspath(path)
    n, k = scene.count, scene.sh.shape[1]
    layout = _Layout.standard(scene.sh_degree)
    names = layout.names[:3] + ["nx", "ny", "nz"] + layout.names[3:]
    rows = np.zeros((n, len(names)), np.float32)  # the file's rows, as plain floats; viewed as records below
    e = layout.sh_end + 3  # +3: the normals sit after x y z
    rows[:, 0:3] = scene.positions
    rows[:, 6:9] = scene.sh[:, 0]
    rows[:, 9:e] = scene.sh[:, 1:].transpose(0, 2, 1).reshape(n, 3 * (k - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        p = scene.opacities.astype(np.float64)
        rows[:, e] = _invert_exactly(_sigmoid32, scene.opacities, np.log(p / (1.0 - p)), -110.0, 40.0)
        rows[:, e + 1:e + 4] = _invert_exactly(_exp32, scene.scales, np.log(scene.scales.astype(np.float64)),
                                               -110.0, 88.0)
    rows[:, e + 4:e + 8] = scene.rotations
    records = rows.view(np.dtype([(name, "f4") for name in names])).reshape(n)
    PlyData([PlyElement.describe(records, "vertex")], text=ascii, byte_order=byte_order,
            comments=["written by gs-ibl (standard 3DGS layout)", *comments, *_colour_declaration(scene)]).write(path)


def _colour_declaration(scene: SplatScene) -> list[str]:
    from .colour_space import DEFAULT_FOR_FILES, colour_space_comment
    return [] if scene.colour_space == DEFAULT_FOR_FILES else [colour_space_comment(scene.colour_space)]
