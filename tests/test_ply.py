"""Standard 3DGS PLY: round trips, activation, every refused input, every repair (real files in tmp_path)."""
from __future__ import annotations

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from gs_ibl_addon.core.formats import SplatFormatError, read_scene
from gs_ibl_addon.core.formats import ply as plymod
from gs_ibl_addon.core.formats.ply import read_ply, write_ply
from gs_ibl_addon.core.formats.repair import MIN_SCALE
from gs_ibl_addon.core.scene import SplatScene
from gs_ibl_addon.core.synthetic import random_scene

FIELDS = ("positions", "scales", "rotations", "opacities", "sh")


def standard_names(degree: int, normals: bool = True) -> list[str]:
    k = (degree + 1) ** 2
    return (["x", "y", "z"] + (["nx", "ny", "nz"] if normals else []) + [f"f_dc_{i}" for i in range(3)]
            + [f"f_rest_{i}" for i in range(3 * (k - 1))] + ["opacity"] + [f"scale_{i}" for i in range(3)]
            + [f"rot_{i}" for i in range(4)])


def write_raw(path, columns: dict[str, np.ndarray], text: bool = False, byte_order: str = "<",
              extra_elements: tuple = (), first: tuple = ()) -> str:
    """A PLY written directly with plyfile from raw per-property columns (no help from the code under test)."""
    n = len(next(iter(columns.values())))
    rec = np.empty(n, [(k, np.asarray(v).dtype.str) for k, v in columns.items()])
    for k, v in columns.items():
        rec[k] = v
    PlyData([*first, PlyElement.describe(rec, "vertex"), *extra_elements], text=text, byte_order=byte_order).write(
        str(path))
    return str(path)


def raw_columns(n: int = 6, degree: int = 0, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    cols = {name: rng.normal(size=n).astype(np.float32) for name in standard_names(degree)}
    for i in range(3):
        cols[f"scale_{i}"] = (cols[f"scale_{i}"] - 4).astype(np.float32)
    return cols


def assert_same(a: SplatScene, b: SplatScene) -> None:
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


# ---------------------------------------------------------------------------------------------------------------
# Round trips

@pytest.mark.parametrize("degree", [0, 1, 2, 3])
@pytest.mark.parametrize("fmt", ["binary_le", "binary_be", "ascii"])
def test_round_trip(tmp_path, degree, fmt):
    scene = random_scene(300, seed=degree, sh_degree=degree)
    path = tmp_path / f"s{degree}.ply"
    write_ply(path, scene, ascii=fmt == "ascii", byte_order=">" if fmt == "binary_be" else "<")
    ply = PlyData.read(str(path))
    assert [p.name for p in ply["vertex"].properties] == standard_names(degree)
    assert ply.text == (fmt == "ascii")
    if fmt != "ascii":
        assert ply.byte_order == (">" if fmt == "binary_be" else "<")
        assert path.stat().st_size - len(ply.header) - 1 == 300 * 4 * len(standard_names(degree))

    back = read_ply(path)
    assert back.sh_degree == degree and back.count == 300 and back.repairs == {}
    # Stored as-is: bit-for-bit.
    for f in ("positions", "sh", "rotations"):
        np.testing.assert_array_equal(getattr(back, f), getattr(scene, f), err_msg=f)
    # Through log/logit in float32: not every float32 is exp()/sigmoid() of a float32, so within a few ulp.
    np.testing.assert_allclose(back.scales, scene.scales, rtol=1e-6)
    np.testing.assert_array_less(np.abs(back.opacities - scene.opacities), 4 * np.spacing(scene.opacities) + 1e-12)
    # A scene that came from a file writes back so that it reads back exactly.
    path2 = tmp_path / f"t{degree}.ply"
    write_ply(path2, back, ascii=fmt == "ascii")
    assert_same(read_ply(path2), back)


def test_read_scene_dispatches_to_read_ply(tmp_path):
    path = tmp_path / "std.ply"
    write_ply(path, random_scene(50, seed=3, sh_degree=1))
    assert_same(read_scene(path), read_ply(path))
    assert read_scene(path).source == str(path)


def test_chunked_reading_compacts_across_chunks(tmp_path, monkeypatch):
    """Many small memory-mapped chunks, with dropped splats in several of them, give the same scene as one chunk."""
    cols = raw_columns(n=50, degree=1, seed=4)
    cols["x"][[3, 7, 8, 31, 49]] = np.nan
    path = write_raw(tmp_path / "c.ply", cols)
    whole = read_ply(path)
    monkeypatch.setattr(plymod, "CHUNK_ROWS", 7)
    chunked = read_ply(path)
    assert chunked.count == 45 and chunked.repairs == {"dropped_nonfinite": 5}
    assert_same(chunked, whole)
    keep = np.setdiff1d(np.arange(50), [3, 7, 8, 31, 49])
    np.testing.assert_array_equal(chunked.positions[:, 1], cols["y"][keep])


# ---------------------------------------------------------------------------------------------------------------
# Activation and layout

def test_activation_values_and_f_rest_order(tmp_path):
    n, degree = 3, 3
    k = 16
    cols = raw_columns(n, degree)
    for i in range(45):
        cols[f"f_rest_{i}"] = np.full(n, 100 + i, np.float32)
    cols["f_dc_0"], cols["f_dc_1"], cols["f_dc_2"] = (np.full(n, v, np.float32) for v in (1.0, 2.0, 3.0))
    cols["opacity"] = np.array([0.0, np.log(3.0), -np.log(3.0)], np.float32)
    cols["scale_0"] = np.log(np.array([0.25, 1.0, 2.0], np.float32))
    q = np.array([[2, 0, 0, 0], [1, 1, 1, 1], [0, 0, 0, -3]], np.float32)
    for i in range(4):
        cols[f"rot_{i}"] = q[:, i]
    s = read_ply(write_raw(tmp_path / "a.ply", cols))

    np.testing.assert_allclose(s.opacities, [0.5, 0.75, 0.25], rtol=1e-6)
    np.testing.assert_allclose(s.scales[:, 0], [0.25, 1.0, 2.0], rtol=1e-6)
    np.testing.assert_allclose(s.scales[:, 1], np.exp(cols["scale_1"].astype(np.float64)), rtol=1e-6)
    np.testing.assert_allclose(s.rotations, [[1, 0, 0, 0], [0.5, 0.5, 0.5, 0.5], [0, 0, 0, -1]], atol=1e-7)
    np.testing.assert_array_equal(s.sh[:, 0], np.tile([1.0, 2.0, 3.0], (n, 1)))
    for c in range(3):
        for kk in range(1, k):
            # channel-major: f_rest index = channel * (K - 1) + (k - 1)
            assert s.sh[0, kk, c] == 100 + c * (k - 1) + kk - 1
    np.testing.assert_array_equal(s.positions, np.stack([cols["x"], cols["y"], cols["z"]], 1))


def test_optional_normals_extra_properties_and_other_types(tmp_path):
    cols = {k: v for k, v in raw_columns(5, 1).items() if k not in ("nx", "ny", "nz")}
    cols["x"] = cols["x"].astype(np.float64)
    cols["opacity"] = cols["opacity"].astype(">f8")
    cols["semantic_id"] = np.arange(5, dtype=np.int32)
    s = read_ply(write_raw(tmp_path / "o.ply", cols, byte_order=">"))
    assert s.count == 5 and s.sh_degree == 1
    np.testing.assert_array_equal(s.positions[:, 0], cols["x"].astype(np.float32))


def test_vertex_after_another_element(tmp_path):
    info = np.array([(7,)], [("version", "i4")])
    cols = raw_columns(4, 0)
    s = read_ply(write_raw(tmp_path / "v.ply", cols, first=(PlyElement.describe(info, "info"),)))
    np.testing.assert_array_equal(s.positions[:, 2], cols["z"])


# ---------------------------------------------------------------------------------------------------------------
# Repairs

def test_repairs_are_applied_and_counted(tmp_path):
    cols = raw_columns(12, 1, seed=2)
    cols["x"][1] = np.nan
    cols["f_rest_4"][2] = np.inf
    cols["opacity"][3] = -np.inf
    cols["scale_2"][4] = 100.0  # exp overflows float32: dropped with the non-finite ones
    cols["scale_0"][5] = -200.0  # exp == 0
    cols["scale_1"][6] = -95.0  # exp is subnormal
    cols["scale_2"][6] = -30.0  # 9e-14 < MIN_SCALE: same splat, counted once
    for i in range(4):
        cols[f"rot_{i}"][7] = 0.0
    s = read_ply(write_raw(tmp_path / "r.ply", cols))
    assert s.repairs == {"dropped_nonfinite": 4, "clamped_scales": 2, "identity_rotations": 1}
    keep = [0, 5, 6, 7, 8, 9, 10, 11]
    assert s.count == len(keep)
    np.testing.assert_array_equal(s.positions[:, 0], cols["x"][keep])
    assert s.scales[1, 0] == MIN_SCALE and s.scales[2, 1] == MIN_SCALE and s.scales[2, 2] == MIN_SCALE
    assert s.scales[2, 0] == np.float32(np.exp(np.float64(cols["scale_0"][6])))
    np.testing.assert_array_equal(s.rotations[3], [1, 0, 0, 0])
    assert all(np.isfinite(getattr(s, f)).all() for f in FIELDS)
    assert (s.scales >= MIN_SCALE).all()
    # The repaired scene is a clean scene: writing and reading it again repairs nothing.
    write_ply(tmp_path / "r2.ply", s)
    again = read_ply(tmp_path / "r2.ply")
    assert again.repairs == {}
    assert_same(again, s)


def test_unnormalised_quaternions_are_activation_not_repair(tmp_path):
    cols = raw_columns(5, 0)
    s = read_ply(write_raw(tmp_path / "q.ply", cols))
    assert s.repairs == {}
    np.testing.assert_allclose(np.linalg.norm(s.rotations, axis=1), 1.0, atol=1e-6)


# ---------------------------------------------------------------------------------------------------------------
# Refused input: one SplatFormatError naming the file, the field and what to do

def expect_error(path, *needles):
    with pytest.raises(SplatFormatError) as e:
        read_ply(path)
    msg = str(e.value)
    assert str(path) in msg
    for needle in needles:
        assert needle in msg, msg
    return msg


def test_error_missing_file(tmp_path):
    expect_error(tmp_path / "nope.ply", "no such file")


def test_error_truncated_binary(tmp_path):
    path = tmp_path / "t.ply"
    write_ply(path, random_scene(100, seed=1, sh_degree=3))
    data = path.read_bytes()
    path.write_bytes(data[:-1000])
    expect_error(path, "truncated", "100 splats", "get the file again")


def test_error_truncated_ascii(tmp_path):
    path = tmp_path / "t.ply"
    write_ply(path, random_scene(20, seed=1, sh_degree=0), ascii=True)
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:-3]))
    expect_error(path, "truncated", "get the file again")


def test_ascii_blocks_blank_lines_and_a_bad_line(tmp_path, monkeypatch):
    """The numpy ASCII reader (block by block) gives what plyfile gives: across block ends, with blank lines and
    no final line end; a bad value is refused naming its line."""
    from gs_ibl_addon.core.formats import ply
    path = tmp_path / "a.ply"
    scene = random_scene(300, seed=4, sh_degree=1)
    write_ply(path, scene, ascii=True)
    want = read_ply(path)
    monkeypatch.setattr(ply, "ASCII_BLOCK", 1000)  # many blocks, each cut at a line end
    head, body = path.read_bytes().split(b"end_header\n")
    lines = body.splitlines()
    odd = tmp_path / "odd.ply"
    odd.write_bytes(head + b"end_header\n" + b"\n".join(lines[:100]) + b"\n\n  \n" + b"\n".join(lines[100:]))
    for p in (path, odd):
        got = read_ply(p)
        for f in ("positions", "scales", "rotations", "opacities", "sh"):
            np.testing.assert_array_equal(getattr(got, f), getattr(want, f))
    lines[150] = lines[150].replace(b" ", b" x ", 1)
    odd.write_bytes(head + b"end_header\n" + b"\n".join(lines) + b"\n")
    expect_error(odd, "line 151 after the header", "numbers")


def test_error_truncated_header(tmp_path):
    path = tmp_path / "h.ply"
    write_ply(path, random_scene(20, seed=1, sh_degree=0))
    path.write_bytes(path.read_bytes()[:60])
    expect_error(path, "not a readable PLY", "early end-of-file")


def test_error_not_a_ply(tmp_path):
    path = tmp_path / "x.ply"
    path.write_bytes(b"\x00\x01garbage" * 10)
    expect_error(path, "not a readable PLY")


def test_error_missing_property(tmp_path):
    cols = raw_columns(4, 0)
    del cols["opacity"]
    msg = expect_error(write_raw(tmp_path / "m.ply", cols), "'opacity'", "missing", "standard layout")
    assert "found" not in msg  # nothing close to suggest


def test_error_misspelt_properties_suggest_close_names(tmp_path):
    cols = raw_columns(4, 0)
    cols["scale1"] = cols.pop("scale_1")
    cols["opacities"] = cols.pop("opacity")
    expect_error(write_raw(tmp_path / "s.ply", cols), "'scale_1' (found 'scale1'", "'opacity' (found 'opacities'",
                 "rename it")


def test_error_mesh_with_faces(tmp_path):
    verts = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [("x", "f4"), ("y", "f4"), ("z", "f4")])
    faces = np.array([([0, 1, 2],)], [("vertex_indices", "i4", (3,))])
    path = tmp_path / "mesh.ply"
    PlyData([PlyElement.describe(verts, "vertex"), PlyElement.describe(faces, "face")]).write(str(path))
    expect_error(path, "mesh", "'face' element", "Stanford PLY")


def test_error_point_cloud(tmp_path):
    cols = {k: np.zeros(3, np.float32) for k in ("x", "y", "z", "nx", "ny", "nz")}
    cols.update({c: np.zeros(3, np.uint8) for c in ("red", "green", "blue")})
    expect_error(write_raw(tmp_path / "pc.ply", cols), "point-cloud", "red", "opacity")


def test_error_no_vertex_element(tmp_path):
    pts = np.zeros(3, [("x", "f4"), ("y", "f4"), ("z", "f4")])
    path = tmp_path / "p.ply"
    PlyData([PlyElement.describe(pts, "point")]).write(str(path))
    expect_error(path, "no 'vertex' element", "point")


@pytest.mark.parametrize("count", [3, 10, 44])
def test_error_f_rest_count(tmp_path, count):
    cols = raw_columns(3, 0)
    for i in range(count):
        cols[f"f_rest_{i}"] = np.zeros(3, np.float32)
    expect_error(write_raw(tmp_path / "f.ply", cols), f"{count} f_rest_*", "0, 9, 24 or 45")


def test_error_f_rest_gap(tmp_path):
    cols = raw_columns(3, 1)
    cols["f_rest_9"] = cols.pop("f_rest_4")
    expect_error(write_raw(tmp_path / "g.ply", cols), "f_rest_4 is missing")


def test_error_list_property(tmp_path):
    cols = raw_columns(3, 0)
    rec = np.empty(3, [(k, "f4") for k in cols if k != "opacity"] + [("opacity", "f4", (2,))])
    for k, v in cols.items():
        rec[k] = v if k != "opacity" else np.stack([v, v], 1)
    path = tmp_path / "l.ply"
    PlyData([PlyElement.describe(rec, "vertex")]).write(str(path))
    expect_error(path, "'opacity' is a list")


def test_error_zero_splats(tmp_path):
    cols = {k: v[:0] for k, v in raw_columns(3, 0).items()}
    expect_error(write_raw(tmp_path / "z.ply", cols), "0 splats")


def test_error_all_splats_nonfinite(tmp_path):
    cols = raw_columns(3, 0)
    cols["y"][:] = np.nan
    expect_error(write_raw(tmp_path / "n.ply", cols), "all 3 splats", "NaN")


# ---------------------------------------------------------------------------------------------------------------
# The numpy ASCII reader against plyfile's own text parser (issue 23)

def plyfile_reference(tmp_path, ascii_path) -> SplatScene:
    """What plyfile's pure-Python text reader makes of ``ascii_path``, through the binary reader: its float32
    columns written as a binary PLY and read back."""
    data = PlyData.read(str(ascii_path))["vertex"].data
    return read_ply(write_raw(tmp_path / "reference.ply", {n: data[n] for n in data.dtype.names}))


def ascii_ply(path, names: list[str], lines: list[bytes], newline: bytes = b"\n", header_extra: tuple = (),
              elements_after: bytes = b"", types: dict | None = None, count: int | None = None) -> str:
    types = types or {}
    head = [b"ply", b"format ascii 1.0", b"comment written by hand", b"obj_info a test", *header_extra,
            f"element vertex {len(lines) if count is None else count}".encode()]
    head += [f"property {types.get(n, 'float')} {n}".encode() for n in names]
    if elements_after:
        head += [b"element face 2", b"property list uchar int vertex_indices"]
    head.append(b"end_header")
    path.write_bytes(newline.join(head + lines) + newline + elements_after)
    return str(path)


def decimal_lines(n: int, names: list[str], seed: int = 0) -> list[bytes]:
    """Values with 6 to 20 significant digits and exponents: most are no float32, some lie near a float32
    rounding boundary (the double then float32 rounding both readers must agree on)."""
    rng = np.random.default_rng(seed)
    lines = []
    for _ in range(n):
        words = []
        for name in names:
            v = rng.normal() * 10.0 ** rng.integers(-6, 4)
            if name.startswith("scale"):
                v = -abs(v) - 3
            if rng.random() < 0.2:  # a float32's midpoint to its neighbour, printed in full
                f = np.float32(v)
                v = (float(f) + float(np.nextafter(f, np.float32(np.inf)))) / 2
                words.append(f"{v:.25g}")
            else:
                words.append(f"{v:.{rng.integers(6, 21)}g}")
        lines.append(" ".join(words).encode())
    return lines


@pytest.mark.parametrize("newline", [b"\n", b"\r\n"])
def test_ascii_same_as_plyfile_decimals_crlf_comments(tmp_path, newline, monkeypatch):
    names = standard_names(3)
    path = ascii_ply(tmp_path / "d.ply", names, decimal_lines(400, names), newline)
    want = plyfile_reference(tmp_path, path)
    assert_same(read_ply(path), want)
    monkeypatch.setattr(plymod, "ASCII_BLOCK", 4096)  # blocks end mid-line: each is completed to its line end
    assert_same(read_ply(path), want)


def test_ascii_trailing_spaces_tabs_and_no_final_line_end(tmp_path):
    names = standard_names(0)
    lines = [b"\t" + ln.replace(b" ", b" \t ", 3) + b"  " for ln in decimal_lines(30, names, seed=2)]
    path = ascii_ply(tmp_path / "t.ply", names, lines)
    path_bytes = (tmp_path / "t.ply").read_bytes().rstrip()
    (tmp_path / "t.ply").write_bytes(path_bytes)
    assert_same(read_ply(path), plyfile_reference(tmp_path, path))


@pytest.mark.parametrize("block", [1 << 20, 700])
def test_ascii_faces_after_vertices(tmp_path, monkeypatch, block):
    """A splat file with another element after the vertices (faces here): the vertices are read, the rest
    left alone, in whichever block the vertices end."""
    monkeypatch.setattr(plymod, "ASCII_BLOCK", block)
    names = standard_names(1)
    path = ascii_ply(tmp_path / "f.ply", names, decimal_lines(50, names, seed=3),
                     elements_after=b"3 0 1 2\n3 2 3 4\n")
    got = read_ply(path)
    assert got.count == 50
    assert_same(got, plyfile_reference(tmp_path, path))


def test_ascii_integer_properties(tmp_path):
    """Integer properties (an int position, uchar colours the layout ignores) read as plyfile reads them."""
    names = standard_names(0) + ["red", "green", "blue"]
    rng = np.random.default_rng(5)
    lines = [ln + b" %d %d %d" % tuple(rng.integers(0, 256, 3)) for ln in decimal_lines(40, standard_names(0), 4)]
    lines = [b"%d" % rng.integers(-(2 ** 30), 2 ** 30) + ln[ln.index(b" "):] for ln in lines]  # x: int32
    path = ascii_ply(tmp_path / "i.ply", names, lines,
                     types={"x": "int", "red": "uchar", "green": "uchar", "blue": "uchar"})
    got = read_ply(path)
    assert_same(got, plyfile_reference(tmp_path, path))
    assert np.all(got.positions[:, 0] == np.round(got.positions[:, 0]))


@pytest.mark.parametrize("block", [1 << 20, 2000])
def test_ascii_garbled_line_named_in_any_block(tmp_path, monkeypatch, block):
    monkeypatch.setattr(plymod, "ASCII_BLOCK", block)
    names = standard_names(0)
    lines = decimal_lines(60, names, seed=6)
    for bad, why in ((b"1.5.2", "a word"), (b"0x1f", "hex"), (b"\xff", "not ASCII"), (b"", "a missing value")):
        garbled = list(lines)
        words = garbled[47].split()
        garbled[47] = b" ".join(words[:5] + ([bad] if bad else []) + words[6:])
        expect_error(ascii_ply(tmp_path / "g.ply", names, garbled), "line 48 after the header", "numbers")
    extra = list(lines)
    extra[47] += b" 1.0"
    expect_error(ascii_ply(tmp_path / "e.ply", names, extra), "line 48 after the header")


def test_ascii_truncated_mid_line_and_mid_file(tmp_path):
    names = standard_names(2)
    path = tmp_path / "t.ply"
    ascii_ply(path, names, decimal_lines(20, names, seed=7))
    data = path.read_bytes()
    path.write_bytes(data[:-40])  # the last line cut short
    expect_error(path, "line 20 after the header", "numbers")
    lines = data.split(b"\n")
    path.write_bytes(b"\n".join(lines[:-6]) + b"\n")  # whole lines missing
    expect_error(path, "truncated", "promises 20 splats", "get the file again")


def test_ascii_blank_lines_in_vertices_before_faces(tmp_path, monkeypatch):
    monkeypatch.setattr(plymod, "ASCII_BLOCK", 900)
    names = standard_names(0)
    lines = decimal_lines(30, names, seed=8)
    path = ascii_ply(tmp_path / "b.ply", names, lines, elements_after=b"3 0 1 2\n3 2 3 4\n")
    want = read_ply(path)
    blank = ascii_ply(tmp_path / "bb.ply", names, lines[:10] + [b""] + lines[10:29] + [b"  "] + lines[29:],
                      elements_after=b"3 0 1 2\n3 2 3 4\n", count=30)
    # plyfile refuses blank lines; ours reads past them (they change no value) and stops after the 30th splat
    assert_same(read_ply(blank), want)
