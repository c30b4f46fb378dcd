"""Every splat format through Blender's importer (bpy module): File > Import gives the right splats, a damaged file
gives the core's message and leaves the .blend as it was, and the SPZ axes option reads SuperSplat's RDF files.

Files are written by the core's own writers (write_ply, write_compressed_ply, write_spz v2/v3/v4, write_splat);
tolerances are each format's quantisation as stated in docs/formats.md and met in tests/test_formats.py.
"""
from __future__ import annotations

import struct

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from gs_ibl_addon.blender.splats.importer import import_matrix  # noqa: E402
from gs_ibl_addon.core.formats import SplatFormatError, read_scene  # noqa: E402
from gs_ibl_addon.core.formats.compressed_ply import CHUNK_SIZE, write_compressed_ply  # noqa: E402
from gs_ibl_addon.core.formats.ply import write_ply  # noqa: E402
from gs_ibl_addon.core.formats.splat import write_splat  # noqa: E402
from gs_ibl_addon.core.formats.spz import read_spz, write_spz  # noqa: E402
from gs_ibl_addon.core.scene import SplatScene, rgb_to_sh_dc  # noqa: E402

N = 600  # three compressed-PLY chunks, the last one partial
SPZ_STEP = 0.5 / 4096  # 24-bit fixed point with 12 fractional bits (positions within +-2048)
BYTE_STEP = 0.5 / 255  # opacity in 8 bits (compressed PLY, SPZ, .splat)


def make_scene(n: int = N, degree: int = 1, seed: int = 0) -> SplatScene:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rgb = rng.uniform(0.05, 0.95, (n, 3))
    sh = np.zeros((n, (degree + 1) ** 2, 3))
    sh[:, 0] = rgb_to_sh_dc(rgb)
    sh[:, 1:] = rng.uniform(-0.5, 0.5, (n, sh.shape[1] - 1, 3))
    return SplatScene(rng.uniform(-3, 3, (n, 3)).astype(np.float32),
                      np.exp(rng.uniform(-5, -1, (n, 3))).astype(np.float32), q.astype(np.float32),
                      rng.uniform(0.05, 0.95, n).astype(np.float32), sh.astype(np.float32))


def _chunk_tolerance(positions: np.ndarray) -> np.ndarray:
    """Per splat and axis: half an 11/10/11-bit step of its 256-splat chunk's range (file order)."""
    n = len(positions)
    pad = np.concatenate([np.arange(n), np.full(-n % CHUNK_SIZE, n - 1)])
    c = positions.astype(np.float64)[pad].reshape(-1, CHUNK_SIZE, 3)
    span = np.repeat(c.max(1) - c.min(1), CHUNK_SIZE, 0)[:n]
    return span / (2 * np.array([2047, 1023, 2047])) + 1e-6


def _write(fmt: str, path, scene: SplatScene):
    """Write ``scene`` as ``fmt``; return positions and opacities in file order, their tolerances, SH degree."""
    if fmt == "ply":
        write_ply(path, scene)
        return scene.positions, scene.opacities, 0.0, 1e-6, scene.sh_degree
    if fmt == "compressed_ply":
        order = write_compressed_ply(path, scene)
        pos = scene.positions[order]
        return pos, scene.opacities[order], _chunk_tolerance(pos), BYTE_STEP + 1e-6, scene.sh_degree
    if fmt.startswith("spz_v"):
        write_spz(path, scene, version=int(fmt[-1]))
        return scene.positions, scene.opacities, SPZ_STEP + 1e-6, BYTE_STEP + 1e-6, scene.sh_degree
    if fmt == "splat":
        write_splat(path, scene)  # float32 positions; degree 0 only
        return scene.positions, scene.opacities, 0.0, BYTE_STEP + 1e-6, 0
    raise AssertionError(fmt)


FORMATS = {"ply": ".ply", "compressed_ply": ".ply", "spz_v2": ".spz", "spz_v3": ".spz", "spz_v4": ".spz",
           "splat": ".splat"}


def _datablock_counts() -> dict[str, int]:
    return {k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "images", "worlds", "materials",
                                                   "node_groups", "collections")}


def _local_positions(obj) -> np.ndarray:
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def _attr(obj, name: str) -> np.ndarray:
    a = obj.data.attributes[name]
    out = np.empty(len(obj.data.vertices) * (1 if a.data_type == "FLOAT" else 4), np.float32)
    a.data.foreach_get("value", out)
    return out.reshape(len(obj.data.vertices), -1)


# ---------------------------------------------------------------------------------------------- good files

@pytest.mark.parametrize("fmt", list(FORMATS))
def test_import_each_format(blender, tmp_path, fmt):
    scene = make_scene()
    path = tmp_path / f"scene_{fmt}{FORMATS[fmt]}"
    pos, opac, pos_tol, opac_tol, degree = _write(fmt, path, scene)
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path)) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.name == path.stem and obj["gs_ibl"]["sh_degree"] == degree
    assert len(obj.data.vertices) == N
    err = np.abs(_local_positions(obj) - pos)
    assert np.all(err <= pos_tol), f"{fmt}: position error {err.max():.3g}"
    assert np.abs(_attr(obj, "gs_opacity")[:, 0] - opac).max() <= opac_tol
    # the file's axes go into the object's transform (default preset 3DGS / OpenCV), not into the data
    np.testing.assert_allclose(np.array(obj.matrix_world), import_matrix("OPENCV", "Z", "-Y", 1.0), atol=1e-6)


# ---------------------------------------------------------------------------------------------- damaged files

def _replace(data: bytes, old: bytes, new: bytes) -> bytes:
    assert old in data and len(old) == len(new)
    return data.replace(old, new, 1)


def _flip_middle_byte(data: bytes) -> bytes:
    b = bytearray(data)
    b[len(b) // 2] ^= 0xFF
    return bytes(b)


def _negative_scale(data: bytes) -> bytes:
    b = bytearray(data)
    b[32 + 12:32 + 16] = struct.pack("<f", -1.0)  # splat 1's first scale
    return bytes(b)


def _v4_version_3(data: bytes) -> bytes:
    return data[:4] + struct.pack("<I", 3) + data[8:]


# (format, what is done to the file): truncation for every format, and a damaged header or payload
DAMAGE = [
    ("ply", "truncated", lambda d: d[:len(d) // 2]),
    ("ply", "misspelt property", lambda d: _replace(d, b"property float opacity", b"property float opacitx")),
    ("compressed_ply", "truncated", lambda d: d[:-1000]),
    ("compressed_ply", "wrong chunk count", lambda d: _replace(d, b"element chunk 3\n", b"element chunk 2\n")),
    ("spz_v2", "truncated", lambda d: d[:-12]),
    ("spz_v3", "truncated", lambda d: d[:-12]),
    ("spz_v3", "bit rot", _flip_middle_byte),
    ("spz_v4", "truncated", lambda d: d[:-1]),
    ("spz_v4", "wrong version", _v4_version_3),
    ("splat", "truncated", lambda d: d[:-5]),
    ("splat", "negative scale", _negative_scale),
]


@pytest.mark.parametrize("fmt, what, damage", DAMAGE, ids=[f"{f}-{w.replace(' ', '_')}" for f, w, _ in DAMAGE])
def test_damaged_file_reports_core_error_and_imports_nothing(blender, tmp_path, fmt, what, damage):
    good = tmp_path / f"good{FORMATS[fmt]}"
    _write(fmt, good, make_scene(seed=3))
    path = tmp_path / f"damaged{FORMATS[fmt]}"
    path.write_bytes(damage(good.read_bytes()))
    with pytest.raises(SplatFormatError) as core:  # what the core says about this file
        read_scene(path)
    before = _datablock_counts()
    with pytest.raises(RuntimeError) as e:  # bpy.ops turns the operator's ERROR report into RuntimeError
        bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path))
    msg = str(e.value)
    assert str(core.value) in msg and str(path) in msg, msg
    assert "Traceback" not in msg, msg  # reported, not crashed
    assert _datablock_counts() == before


def test_one_bad_file_among_several_imports_none(blender, tmp_path):
    write_spz(tmp_path / "a.spz", make_scene(seed=4))
    write_ply(tmp_path / "b.ply", make_scene(seed=5))
    (tmp_path / "c.splat").write_bytes(b"\0" * 33)
    before = _datablock_counts()
    files = [{"name": n} for n in ("a.spz", "b.ply", "c.splat")]
    with pytest.raises(RuntimeError, match="c.splat"):
        bpy.ops.gs_ibl.import_splats(native=False, directory=str(tmp_path), files=files)
    assert _datablock_counts() == before
    assert bpy.ops.gs_ibl.import_splats(native=False, directory=str(tmp_path), files=files[:2]) == {"FINISHED"}
    assert _datablock_counts()["objects"] == before["objects"] + 2


# ---------------------------------------------------------------------------------------------- SPZ axes

def test_spz_axes_option_reads_supersplat_rdf_files(blender, tmp_path):
    """An .spz stored RDF (SuperSplat, splat-transform) comes in right with SPZ Axes = RDF and upside down (y, z
    negated) as the spec's RUB; a spec-conforming RUB file comes in right by default."""
    scene = make_scene(seed=6)
    rdf, rub = tmp_path / "supersplat.spz", tmp_path / "spec.spz"
    write_spz(rdf, scene, version=3, coordinates="RDF")
    write_spz(rub, scene, version=3, coordinates="RUB")
    tol = SPZ_STEP + 1e-6

    def imported(path, **kw):
        assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), **kw) == {"FINISHED"}
        return bpy.context.active_object

    obj = imported(rdf, spz_axes="RDF")
    assert np.abs(_local_positions(obj) - scene.positions).max() <= tol
    # rotations too (the flip is a 180-degree turn of everything): smallest-three, 9 bits + sign
    d = np.abs(np.sum(_attr(obj, "gs_rotation").astype(np.float64) * scene.rotations, 1))
    assert (2 * np.arccos(np.clip(d, 0, 1))).max() <= 0.005
    wrong = imported(rdf, spz_axes="RUB")
    assert np.abs(_local_positions(wrong) - scene.positions * [1, -1, -1]).max() <= tol
    assert np.abs(_local_positions(imported(rub)) - scene.positions).max() <= tol  # default: RUB (the spec)


def test_spz_axes_default_keeps_a_v4_coordinate_record(blender, tmp_path):
    """Default (RUB): a version-4 file that names its system (Adobe's record, here RDF) is read in that system."""
    scene = make_scene(seed=7)
    plain = tmp_path / "plain.spz"
    write_spz(plain, scene, version=4, coordinates="RDF")
    blob = plain.read_bytes()
    record = struct.pack("<III", 0xADBE0003, 4, 6)  # SPZ_ADOBE_coordinate_system, 6 = RDF
    header = bytearray(blob[:32])
    header[14] |= 0x2  # flags: has extensions
    header[16:20] = struct.pack("<I", 32 + len(record))  # the table of contents moves behind the record
    tagged = tmp_path / "tagged.spz"
    tagged.write_bytes(bytes(header) + record + blob[32:])
    assert np.abs(read_spz(tagged).positions - scene.positions).max() <= SPZ_STEP + 1e-6  # the core agrees
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(tagged)) == {"FINISHED"}
    assert np.abs(_local_positions(bpy.context.active_object) - scene.positions).max() <= SPZ_STEP + 1e-6


def test_spz_axes_is_ignored_for_other_formats(blender, tmp_path):
    scene = make_scene(seed=8)
    path = tmp_path / "s.ply"
    write_ply(path, scene)
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path), spz_axes="RDF") == {"FINISHED"}
    np.testing.assert_array_equal(_local_positions(bpy.context.active_object), scene.positions)


def test_sog_imports_with_blenders_own_webp_decoder(blender, tmp_path, monkeypatch):
    """SOG's WebP images decode through Blender's image loader where neither OpenImageIO nor Pillow is importable
    (the bpy module from PyPI, distributions' builds): same bytes, same splats as the libraries give."""
    from gs_ibl_addon.blender.splats.webp_decoder import decode_webp
    from gs_ibl_addon.core.formats import webp
    from gs_ibl_addon.core.formats.sog import read_sog, write_sog
    rng = np.random.default_rng(3)
    rgba = rng.integers(0, 256, (21, 34, 4), dtype=np.uint8)
    rgba[rgba[..., 3] == 0, :3] = 0  # libwebp drops RGB under alpha 0 (webp.py's note)
    data = webp.encode_lossless(rgba)
    np.testing.assert_array_equal(decode_webp(data), rgba)
    with pytest.raises(ValueError, match="cannot be decoded"):
        decode_webp(b"RIFF\x10\x00\x00\x00WEBPVP8L" + b"\x00" * 8)
    scene = make_scene()
    path = tmp_path / "scene.sog"
    write_sog(path, scene)
    webp.drop_decoder(decode_webp)
    by_library = read_sog(path)
    webp.use_decoder(decode_webp)
    monkeypatch.setattr(webp, "_oiio", lambda: None)
    monkeypatch.setattr(webp, "_pillow", lambda: None)
    by_blender = read_sog(path)
    for field in ("positions", "scales", "rotations", "opacities", "sh"):
        np.testing.assert_array_equal(getattr(by_blender, field), getattr(by_library, field), err_msg=field)
    assert bpy.ops.gs_ibl.import_splats(native=False, filepath=str(path)) == {"FINISHED"}
    assert len(bpy.context.active_object.data.vertices) == scene.count
    import gs_ibl_addon
    gs_ibl_addon.unregister()
    assert decode_webp not in webp._decoders
    gs_ibl_addon.register()
