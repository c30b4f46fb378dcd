"""Splat formats users bring: SuperSplat compressed PLY, Niantic SPZ (v2/v3/v4), antimatter15 .splat.

* A real SuperSplat file (the guitar) is decoded and checked against its own chunk ranges, and re-encoded
  with our writer to the same packed words (a bit-level check of our reading of the layout).
* Two SPZ files written by Niantic's spz library (v3 and v4; from PlayCanvas splat-transform's test fixtures,
  MIT licence, Copyright (c) 2011-2026 PlayCanvas Ltd.) decode to the values they were made from.
* Random scenes go through each writer and back within the format's quantisation error, stated per field.
* Damaged files of each format give one SplatFormatError naming the file and what is wrong.
"""
from __future__ import annotations

import gzip
import os
import struct

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from gs_ibl_addon.core.formats import SplatFormatError, read_scene
from gs_ibl_addon.core.formats.compressed_ply import CHUNK_SIZE, _unpack_rotation, write_compressed_ply
from gs_ibl_addon.core.formats.splat import read_splat, write_splat
from gs_ibl_addon.core.formats.spz import _axis_flips, _flip, read_spz, write_spz
from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.scene import SH_C0, SplatScene, quat_to_matrix, rgb_to_sh_dc, sh_dc_to_rgb
from gs_ibl_addon.core.sh import eval_sh_color

GUITAR = os.path.join(os.path.dirname(__file__), "data", "guitar.compressed.ply")

# Written by Niantic's spz (Adobe's WASM build) with from=RDF: 4 splats on a 2x2 grid, positions ((i%2)-1, 0,
# (i//2)-1), scale 0.1, opacity 0.9, rendered colour ((i%2+1)/3, (i//2+1)/3, 0.5), identity rotation.
SPZ_V3_NIANTIC = bytes.fromhex(
    "1f8b0800000000000003f3730f0e60666060600162061e20fef01fc4126080020198081278060499990dd3321b32a7354c9bd6508d04"
    "80d20790310027c3b78960000000")
SPZ_V4_NIANTIC = bytes.fromhex(
    "4e4753500400000004000000000c000520000000000000000000000000000000250000000000000024000000000000000d0000000000"
    "0000040000000000000015000000000000000c0000000000000011000000000000000c0000000000000014000000000000001000000000"
    "00000028b52ffd2024e50000b000f0ff00000000100000000000000000100000f0ff00010064d00428b52ffd2004210000e6e6e6e628b5"
    "2ffd200c61000069698096698069968096968028b52ffd200c450000107b7b01001bc00228b52ffd20105d000028000000c00001008cab05")


def random_scene(n: int, degree: int, seed: int = 0) -> SplatScene:
    """core.synthetic.random_scene over +-5 (SPZ's fixed point and the chunk ranges see real spans), with DC colours
    reaching a little outside [0, 1] as trained scenes' do (compressed PLY keeps them; .splat clamps them)."""
    scene = synthetic.random_scene(n, seed, degree, extent=5.0)
    scene.sh[:, 0] = rgb_to_sh_dc(np.random.default_rng([seed, 1]).uniform(-0.1, 1.1, (n, 3)))  # not tied to positions
    return scene


def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle between unit quaternions (q and -q are the same rotation)."""
    d = np.abs(np.sum(a.astype(np.float64) * b, 1))
    return 2 * np.arccos(np.clip(d, 0, 1))


def rgb_of(scene: SplatScene) -> np.ndarray:
    return sh_dc_to_rgb(scene.sh[:, 0])


def assert_error(path, call, *words: str) -> str:
    with pytest.raises(SplatFormatError) as info:
        call(str(path))
    msg = str(info.value)
    assert msg.startswith(f"{path}: "), msg
    assert msg.endswith(")") and " (" in msg, msg  # "<file>: <what is wrong> (<what to do>)"
    for w in words:
        assert w in msg, msg
    return msg


# ---------------------------------------------------------------- the real SuperSplat file


@pytest.fixture(scope="module")
def guitar():
    return read_scene(GUITAR), PlyData.read(GUITAR)


def test_guitar_decodes_within_its_chunk_ranges(guitar):
    scene, ply = guitar
    assert scene.count == 90_854 and scene.sh_degree == 0 and scene.source == GUITAR
    chunk = ply["chunk"].data
    ci = np.arange(scene.count) // CHUNK_SIZE
    eps = 1e-6
    for i, axis in enumerate("xyz"):
        lo, hi = chunk[f"min_{axis}"][ci], chunk[f"max_{axis}"][ci]
        assert np.all(scene.positions[:, i] >= lo - eps) and np.all(scene.positions[:, i] <= hi + eps), axis
        log_s = np.log(scene.scales[:, i].astype(np.float64))
        assert np.all(log_s >= chunk[f"min_scale_{axis}"][ci] - 1e-5)
        assert np.all(log_s <= chunk[f"max_scale_{axis}"][ci] + 1e-5)
    rgb = rgb_of(scene)
    for i, ch in enumerate("rgb"):
        lo, hi = chunk[f"min_{ch}"][ci], chunk[f"max_{ch}"][ci]
        assert np.all(rgb[:, i] >= lo - 1e-5) and np.all(rgb[:, i] <= hi + 1e-5), ch
    # The colour ranges are not clamped to [0, 1]: the DC colour of a trained scene goes a little outside.
    assert rgb.min() < 0 and rgb.max() > 1 and 0.2 < rgb.mean() < 0.6
    assert np.all(scene.scales > 0) and np.all(np.isfinite(scene.positions))
    np.testing.assert_allclose(np.linalg.norm(scene.rotations, axis=1), 1.0, atol=1e-6)
    assert np.all(scene.opacities > 0) and np.all(scene.opacities < 1)
    # A trained capture spans the whole opacity range; the alpha byte steps by 1/255.
    assert scene.opacities.min() < 0.01 and scene.opacities.max() > 0.99
    steps = scene.opacities * 255
    assert np.abs(steps[(steps > 1) & (steps < 254)] - np.round(steps[(steps > 1) & (steps < 254)])).max() < 1e-3


def test_guitar_reencodes_to_the_same_packed_words(guitar, tmp_path):
    """Our writer, fed the decoded guitar in file order, must reproduce SuperSplat's packed words: this ties our
    reading of every bit field and value mapping to a real file rather than to our own writer."""
    scene, ply = guitar
    out = tmp_path / "again.compressed.ply"
    write_compressed_ply(out, scene, sort=False)
    again = PlyData.read(str(out), mmap=False)
    for name in ("packed_position", "packed_scale", "packed_color"):
        np.testing.assert_array_equal(again["vertex"].data[name], ply["vertex"].data[name], err_msg=name)
    # Rotation: where two components are equal within a quantisation step, either may be stored as the "largest";
    # such words differ but must decode to the same quaternion within one quantisation step.
    mine, theirs = again["vertex"].data["packed_rotation"], ply["vertex"].data["packed_rotation"]
    d = mine != theirs
    assert d.mean() < 0.005 and np.all((mine[d] >> 30) != (theirs[d] >> 30))
    assert angle(_unpack_rotation(mine[d]), _unpack_rotation(theirs[d])).max() <= 0.005  # one 10-bit step
    for name in ply["chunk"].data.dtype.names:
        np.testing.assert_allclose(again["chunk"].data[name], ply["chunk"].data[name], rtol=0, atol=1e-6, err_msg=name)


# ---------------------------------------------------------------- SPZ written by Niantic's library


@pytest.mark.parametrize("blob", [SPZ_V3_NIANTIC, SPZ_V4_NIANTIC], ids=["v3", "v4"])
def test_spz_from_niantic_library(blob, tmp_path):
    path = tmp_path / "minimal.spz"
    path.write_bytes(blob)
    scene = read_scene(path)  # default: the file is RUB (spec) and becomes RDF
    i = np.arange(4)
    want = np.stack([i % 2 - 1.0, np.zeros(4), i // 2 - 1.0], 1)
    np.testing.assert_allclose(scene.positions, want, atol=0.5 / 4096)
    np.testing.assert_allclose(scene.scales, 0.1, rtol=np.exp(1 / 32) - 1)
    np.testing.assert_allclose(scene.opacities, 0.9, atol=0.5 / 255)
    np.testing.assert_allclose(np.abs(scene.rotations), [[1, 0, 0, 0]] * 4, atol=2e-3)
    want_rgb = np.stack([(i % 2 + 1) / 3, (i // 2 + 1) / 3, np.full(4, 0.5)], 1)
    np.testing.assert_allclose(rgb_of(scene), want_rgb, atol=SH_C0 * 0.5 / (255 * 0.15) + 1e-6)
    raw = read_spz(path, coordinates="RDF")  # read without conversion, z keeps the stored (RUB) sign
    np.testing.assert_allclose(raw.positions[:, 2], -want[:, 2], atol=0.5 / 4096)


# ---------------------------------------------------------------- round trips


def test_compressed_ply_round_trip(tmp_path):
    scene = random_scene(3000, 3, seed=1)
    for sort in (False, True):
        path = tmp_path / f"s{sort}.compressed.ply"
        order = write_compressed_ply(path, scene, sort=sort)
        got = read_scene(path)
        ref = scene.subset(order)
        assert got.count == ref.count and got.sh_degree == 3
        pad = np.concatenate([np.arange(ref.count), np.full(-ref.count % CHUNK_SIZE, ref.count - 1)])

        def chunk_span(a):  # per splat: its chunk's max - min, the range the bits are spread over
            c = a[pad].reshape(-1, CHUNK_SIZE, a.shape[1])
            return np.repeat(c.max(1) - c.min(1), CHUNK_SIZE, 0)[:ref.count]

        steps = np.array([2047, 1023, 2047])  # 11/10/11 bits
        tol = chunk_span(ref.positions.astype(np.float64)) / (2 * steps) + 1e-6
        assert np.all(np.abs(got.positions - ref.positions) <= tol)
        log_ref = np.log(ref.scales.astype(np.float64))
        tol = chunk_span(log_ref) / (2 * steps) + 1e-5
        assert np.all(np.abs(np.log(got.scales) - log_ref) <= tol)
        tol = chunk_span(rgb_of(ref)) / (2 * 255) + 1e-6  # 8 bits over the chunk's colour range
        assert np.all(np.abs(rgb_of(got) - rgb_of(ref)) <= tol)
        assert np.abs(got.opacities - ref.opacities).max() <= 0.5 / 255 + 1e-6
        assert angle(got.rotations, ref.rotations).max() <= 0.005  # 10 bits over +-1/sqrt2 per component
        assert np.abs(got.sh[:, 1:] - ref.sh[:, 1:]).max() <= 1 / 64 + 1e-6  # 8 bits over [-4, 4]
    # Sorting matters: Morton order makes chunks compact, so positions come back more precisely on average.
    err = [np.abs(read_scene(tmp_path / f"s{s}.compressed.ply").positions
                  - scene.subset(write_compressed_ply(tmp_path / "x.ply", scene, sort=s)).positions).mean()
           for s in (False, True)]
    assert err[1] < 0.75 * err[0], err


@pytest.mark.parametrize("version", [2, 3, 4])
def test_spz_round_trip(version, tmp_path):
    scene = random_scene(3000, 3, seed=2)
    path = tmp_path / f"v{version}.spz"
    write_spz(path, scene, version=version)
    got = read_scene(path)
    assert got.count == scene.count and got.sh_degree == 3 and got.repairs == {}
    assert np.abs(got.positions - scene.positions).max() <= 0.5 / 4096 + 1e-6  # 12 fractional bits
    assert np.abs(got.opacities - scene.opacities).max() <= 0.5 / 255 + 1e-6
    assert np.abs(got.sh[:, 0] - scene.sh[:, 0]).max() <= 0.5 / (255 * 0.15) + 1e-5  # f_dc * 0.15 in 8 bits
    assert np.abs(np.log(got.scales) - np.log(scene.scales)).max() <= 1 / 32 + 1e-5  # log scale in 1/16 steps
    a = angle(got.rotations, scene.rotations)
    if version >= 3:
        assert a.max() <= 0.005  # smallest three, 9 bits + sign over +-1/sqrt2
    else:
        # x, y, z in 8 bits with w rebuilt from them: fine unless w is small, where the error grows.
        assert a[np.abs(scene.rotations[:, 0]) >= 0.5].max() <= 0.03 and a.max() <= 0.25
    # SH: degree 1 in 5 bits (bucket 8/128), higher degrees in 4 bits (bucket 16/128), plus rounding to 1/128.
    err = np.abs(got.sh[:, 1:] - scene.sh[:, 1:])
    assert err[:, :3].max() <= 4.5 / 128 + 1e-6 and err[:, 3:].max() <= 8.5 / 128 + 1e-6


def test_spz_coordinates(tmp_path):
    scene = random_scene(500, 2, seed=3)
    write_spz(tmp_path / "rdf.spz", scene, coordinates="RDF")
    write_spz(tmp_path / "rub.spz", scene)  # the specification's convention
    rdf, rub = read_spz(tmp_path / "rdf.spz", coordinates="RDF"), read_spz(tmp_path / "rub.spz")
    np.testing.assert_array_equal(rdf.positions, rub.positions)
    np.testing.assert_allclose(angle(rdf.rotations, rub.rotations), 0, atol=1e-3)
    # SH quantisation rounds x and -x to buckets differently, so each only agrees with the scene within its error.
    for got in (rdf, rub):
        assert np.abs(got.sh[:, 1:] - scene.sh[:, 1:]).max() <= 8.5 / 128 + 1e-6
    # Read as stored (no conversion), the RUB file has y and z negated...
    stored = read_spz(tmp_path / "rub.spz", coordinates="RDF")
    np.testing.assert_allclose(stored.positions, scene.positions * [1, -1, -1], atol=0.5 / 4096 + 1e-6)


def test_axis_flip_is_a_rotation_of_everything():
    """A flip of two axes must move orientations and view-dependent colour with the positions."""
    scene = random_scene(200, 3, seed=4)
    f = _axis_flips("RUB")
    pos, rot, rest = scene.positions.copy(), scene.rotations.copy(), scene.sh[:, 1:].copy()
    _flip(pos, rot, rest, f)
    F = np.diag(f)
    np.testing.assert_allclose(quat_to_matrix(rot), F @ quat_to_matrix(scene.rotations) @ F, atol=1e-6)
    d = np.random.default_rng(5).normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sh = np.concatenate([scene.sh[:, :1], rest], 1)
    np.testing.assert_allclose(eval_sh_color(sh, d * f), eval_sh_color(scene.sh, d), atol=1e-5)


def test_splat_round_trip(tmp_path):
    scene = random_scene(3000, 2, seed=6)
    path = tmp_path / "s.splat"
    write_splat(path, scene)
    assert os.path.getsize(path) == 32 * scene.count
    got = read_scene(path)
    assert got.sh_degree == 0 and got.repairs == {}
    np.testing.assert_array_equal(got.positions, scene.positions)  # float32, exact
    np.testing.assert_array_equal(got.scales, scene.scales)
    # Colour: 8 bits of the DC colour clamped to [0, 1]; view-dependent colour is not stored.
    assert np.abs(rgb_of(got) - np.clip(rgb_of(scene), 0, 1)).max() <= 0.5 / 255 + 1e-6
    assert np.abs(got.opacities - scene.opacities).max() <= 0.5 / 255 + 1e-6
    assert angle(got.rotations, scene.rotations).max() <= 0.02  # 4 components in 1/128 steps


def test_splat_repairs(tmp_path):
    scene = random_scene(10, 0, seed=7)
    scene.positions[2] = np.nan
    scene.scales[3, 1] = 0.0
    path = tmp_path / "r.splat"
    write_splat(path, scene)
    raw = bytearray(path.read_bytes())
    raw[4 * 32 + 28:4 * 32 + 32] = bytes([128] * 4)  # a zero quaternion
    path.write_bytes(bytes(raw))
    got = read_splat(path)
    assert got.count == 9 and got.repairs == {"dropped_nonfinite": 1, "clamped_scales": 1, "identity_rotations": 1}
    assert np.all(got.scales > 0)
    np.testing.assert_array_equal(got.rotations[3], [1, 0, 0, 0])


# ---------------------------------------------------------------- damaged files


def test_compressed_ply_damage(tmp_path, guitar):
    data = open(GUITAR, "rb").read()
    cut = tmp_path / "cut.compressed.ply"
    cut.write_bytes(data[:-1000])
    assert_error(cut, read_scene, "truncated", "90854 splats")
    wrong = tmp_path / "count.compressed.ply"
    wrong.write_bytes(data.replace(b"element chunk 355", b"element chunk 354", 1))
    assert_error(wrong, read_scene, "354 chunks for 90854 splats", "expected 355")

    scene = random_scene(300, 1, seed=8)
    good = tmp_path / "good.compressed.ply"
    write_compressed_ply(good, scene)
    ply = PlyData.read(str(good), mmap=False)
    chunk, vertex, sh = (ply[name].data for name in ("chunk", "vertex", "sh"))

    def rewrite(name, *elements):
        p = tmp_path / name
        PlyData(list(elements), text=False).write(str(p))
        return p

    no_colour = np.empty(len(vertex), [(n, "<u4") for n in ("packed_position", "packed_rotation", "packed_scale")])
    for n in no_colour.dtype.names:
        no_colour[n] = vertex[n]
    p = rewrite("missing.ply", PlyElement.describe(chunk, "chunk"), PlyElement.describe(no_colour, "vertex"))
    assert_error(p, read_scene, "no property 'packed_color'")
    as_float = vertex.astype([(n, "<f4") for n in vertex.dtype.names])
    p = rewrite("type.ply", PlyElement.describe(chunk, "chunk"), PlyElement.describe(as_float, "vertex"))
    assert_error(p, read_scene, "'vertex.packed_position' is float32, expected uint32")
    p = rewrite("sh.ply", PlyElement.describe(chunk, "chunk"), PlyElement.describe(vertex, "vertex"),
                PlyElement.describe(sh[:-1], "sh"))
    assert_error(p, read_scene, "'sh' element has 299 rows for 300 splats")
    bad = chunk.copy()
    bad["max_x"][1] = np.inf
    p = rewrite("inf.ply", PlyElement.describe(bad, "chunk"), PlyElement.describe(vertex, "vertex"))
    assert_error(p, read_scene, "non-finite ranges", "chunk 1")


def _legacy(version=3, n=4, degree=0, payload=None):
    body = payload if payload is not None else bytes(n * (9 + 1 + 3 + 3 + (3 if version == 2 else 4)))
    return gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, version, n, degree, 12, 0, 0) + body)


def test_spz_damage(tmp_path):
    def check(name, blob, *words):
        p = tmp_path / name
        p.write_bytes(blob)
        return assert_error(p, read_spz, *words)

    check("magic.spz", gzip.compress(b"XXXX" + bytes(60)), "bad magic")
    check("notspz.spz", b"hello world, not a splat", "not an SPZ file")
    check("v1.spz", _legacy(version=1), "SPZ version 1")
    check("v9.spz", _legacy(version=9), "SPZ version 9")
    check("short.spz", _legacy(payload=bytes(50)), "ends after 66 of the 96 bytes", "truncated")
    check("count.spz", _legacy(n=3, payload=bytes(80)), "bytes follow the data of the 3 splats")
    check("zero.spz", _legacy(n=0, payload=b""), "0 splats")
    check("degree.spz", _legacy(degree=7), "SH degree 7")
    check("gzipcut.spz", SPZ_V3_NIANTIC[:-12], "gzip stream is truncated or damaged")
    check("v4cut.spz", SPZ_V4_NIANTIC[:-1], "truncated")
    check("v4short.spz", SPZ_V4_NIANTIC[:20], "truncated")
    check("v4ver.spz", SPZ_V4_NIANTIC[:4] + struct.pack("<I", 3) + SPZ_V4_NIANTIC[8:], "SPZ version 3", "NGSP")
    check("v4count.spz", SPZ_V4_NIANTIC[:8] + struct.pack("<I", 5) + SPZ_V4_NIANTIC[12:],
          "stream 0 holds 36 bytes; 5 splats need 45")
    check("v4streams.spz", SPZ_V4_NIANTIC[:15] + b"\x06" + SPZ_V4_NIANTIC[16:], "6 attribute streams")
    check("v4zstd.spz", SPZ_V4_NIANTIC[:-20] + bytes(20), "does not decompress")


def test_splat_damage(tmp_path):
    scene = random_scene(4, 0, seed=9)
    good = tmp_path / "good.splat"
    write_splat(good, scene)
    data = good.read_bytes()

    def check(name, blob, *words):
        p = tmp_path / name
        p.write_bytes(blob)
        return assert_error(p, read_scene, *words)

    check("empty.splat", b"", "empty")
    check("cut.splat", data[:-5], "123 bytes is not a whole number of 32-byte splats")
    neg = bytearray(data)
    neg[32 + 12:32 + 16] = struct.pack("<f", -1.0)
    check("neg.splat", bytes(neg), "1 of 4 splats have negative scales", "splat 1")
    nan = np.frombuffer(data, np.uint8).copy().view(np.float32).reshape(4, 8)
    nan[:, 0] = np.nan
    check("nan.splat", nan.tobytes(), "all 4 splats have non-finite")


# ---------------------------------------------------------------- less common variants


def test_compressed_ply_without_colour_ranges(tmp_path):
    """Files from before per-chunk colour ranges store the colour itself (clamped to [0, 1]) in packed_color."""
    scene = random_scene(600, 0, seed=10)
    good = tmp_path / "ranged.compressed.ply"
    order = write_compressed_ply(good, scene)
    ply = PlyData.read(str(good), mmap=False)
    base = [n for n in ply["chunk"].data.dtype.names if not n.endswith(("_r", "_g", "_b"))]
    assert len(base) == 12
    chunk = np.empty(ply["chunk"].count, [(n, "<f4") for n in base])
    for n in base:
        chunk[n] = ply["chunk"].data[n]
    vertex = ply["vertex"].data.copy()
    rgb = np.clip(rgb_of(scene.subset(order)), 0, 1)
    byte = np.round(rgb * 255).astype(np.uint32)
    alpha = vertex["packed_color"] & 255
    vertex["packed_color"] = (byte[:, 0] << 24) | (byte[:, 1] << 16) | (byte[:, 2] << 8) | alpha
    old = tmp_path / "old.compressed.ply"
    PlyData([PlyElement.describe(chunk, "chunk"), PlyElement.describe(vertex, "vertex")], text=False).write(str(old))
    got = read_scene(old)
    assert np.abs(rgb_of(got) - rgb).max() <= 0.5 / 255 + 1e-6
    np.testing.assert_array_equal(got.positions, read_scene(good).positions)


def test_spz_sh_degree_4_is_cut_to_3(tmp_path):
    n, rng = 2, np.random.default_rng(11)
    sh = rng.integers(0, 256, (n, 24, 3), dtype=np.uint8)
    body = bytes(9 * n) + bytes([200] * n) + bytes([128] * 3 * n) + bytes([100] * 3 * n) + bytes(4 * n) + sh.tobytes()
    path = tmp_path / "deg4.spz"
    path.write_bytes(_legacy(version=3, n=n, degree=4, payload=body))
    got = read_spz(path, coordinates="RDF")
    assert got.sh_degree == 3 and got.repairs == {"sh_degree_4_dropped": n}
    np.testing.assert_array_equal(got.sh[:, 1:], (sh[:, :15].astype(np.float32) - 128) / 128)


def test_spz_v4_coordinate_extension(tmp_path):
    """A version 4 file that names its coordinate system (Adobe's extension record) is read in that system."""
    scene = random_scene(50, 1, seed=12)
    plain = tmp_path / "rdf.spz"
    write_spz(plain, scene, version=4, coordinates="RDF")
    blob = plain.read_bytes()
    record = struct.pack("<III", 0xADBE0003, 4, 6)  # 6 = RDF
    header = bytearray(blob[:32])
    header[14] |= 0x2
    header[16:20] = struct.pack("<I", 32 + len(record))
    tagged = tmp_path / "tagged.spz"
    tagged.write_bytes(bytes(header) + record + blob[32:])
    np.testing.assert_array_equal(read_spz(tagged).positions, read_spz(plain, coordinates="RDF").positions)
    assert np.abs(read_spz(tagged).positions - scene.positions).max() <= 0.5 / 4096 + 1e-6


def test_guitar_converts_to_standard_ply(guitar, tmp_path):
    """convert: compressed PLY -> standard 3DGS PLY (ply.write_ply) keeps the decoded splats."""
    from gs_ibl_addon.core.formats.ply import read_ply, write_ply
    scene, _ = guitar
    out = tmp_path / "guitar.ply"
    write_ply(out, scene)
    back = read_ply(out)
    assert back.count == scene.count
    np.testing.assert_array_equal(back.positions, scene.positions)
    np.testing.assert_allclose(back.scales, scene.scales, rtol=1e-6)
    np.testing.assert_allclose(back.opacities, scene.opacities, atol=1e-6)
    np.testing.assert_allclose(back.sh, scene.sh, atol=1e-5)
    np.testing.assert_allclose(angle(back.rotations, scene.rotations), 0, atol=1e-3)


def test_axes_declaration_round_trips(tmp_path):
    """A PLY written with the axes comment says its axes; a damaged or foreign declaration is not believed."""
    from gs_ibl_addon.core.formats.axes import axes_comment, declared_axes
    from gs_ibl_addon.core.formats.ply import read_ply, write_ply
    from gs_ibl_addon.core.synthetic import random_scene
    scene = random_scene(20, sh_degree=1)
    path = tmp_path / "a.ply"
    write_ply(path, scene, comments=(axes_comment("-Z", "Y"),))
    assert declared_axes(path) == ("-Z", "Y")
    np.testing.assert_array_equal(read_ply(path).positions, scene.positions)  # the comment changes no data
    write_ply(path, scene)
    assert declared_axes(path) is None
    with pytest.raises(ValueError, match="two different axes"):
        axes_comment("Y", "-Y")
    bad = tmp_path / "b.ply"
    bad.write_bytes(b"ply\nformat ascii 1.0\ncomment gs_ibl axes forward=Q up=Z\nend_header\n")
    assert declared_axes(bad) is None and declared_axes(tmp_path / "missing.ply") is None
