"""A corpus of bad inputs a new user could bring, generated (no committed binaries): damaged splat files of every
format and bad numbers for every option, each a command line that must be refused with one line and exit code 2.

``file_cases(folder)`` writes the damaged files and returns (name, path); ``command_cases(folder)`` returns
(name, argv) for option and output mistakes, given a good small scene written into ``folder``.
"""
from __future__ import annotations

import gzip
import io
import json
import os
import struct
import zipfile

import numpy as np

from gs_ibl_addon.core import synthetic
from gs_ibl_addon.core.formats.gltf import write_glb
from gs_ibl_addon.core.formats.ksplat import write_ksplat
from gs_ibl_addon.core.formats.ply import write_ply
from gs_ibl_addon.core.formats.sog import write_sog
from gs_ibl_addon.core.formats.splat import write_splat
from gs_ibl_addon.core.formats.spz import write_spz

PLY_PROPS = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
             "rot_0", "rot_1", "rot_2", "rot_3"]


def good_scene(n: int = 300):
    return synthetic.random_scene(n, 7, 1, extent=2.0)


def _ply_header(count, props=PLY_PROPS, fmt="binary_little_endian", types="float") -> bytes:
    lines = ["ply", f"format {fmt} 1.0", f"element vertex {count}"]
    lines += [f"property {types} {p}" for p in props]
    return ("\n".join(lines + ["end_header"]) + "\n").encode()


def _ply_rows(values: np.ndarray, props=PLY_PROPS) -> bytes:
    return _ply_header(len(values), props) + values.astype("<f4").tobytes()


def _glb(doc: dict, binary: bytes, length: int | None = None) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total if length is None else length) + struct.pack("<II", len(text), 0x4E4F534A)
            + text + struct.pack("<II", len(binary), 0x004E4942) + binary)


def _glb_parts(path: str) -> tuple[dict, bytes]:
    data = open(path, "rb").read()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    return doc, data[20 + n + 8:]


def _zip(entries: dict[str, bytes]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for name, data in entries.items():
            z.writestr(name, data)
    return out.getvalue()


def file_cases(folder: str) -> list[tuple[str, str]]:
    """Damaged files of every format, written into ``folder``: (case name, path)."""
    os.makedirs(folder, exist_ok=True)
    scene = good_scene()
    cases: dict[str, tuple[str, bytes | None]] = {}
    rng = np.random.default_rng(3)
    rows = rng.normal(size=(50, len(PLY_PROPS)))

    def put(name: str, filename: str, data: bytes | None) -> None:
        cases[name] = (filename, data)

    put("missing file", "missing.ply", None)
    put("empty file", "empty.ply", b"")
    put("ply: 10^12 vertices claimed", "huge.ply", _ply_header(10 ** 12) + b"\0" * 1000)
    put("ply: negative count", "negative.ply", _ply_header(-5) + b"\0" * 100)
    put("ply: truncated binary", "cut.ply", _ply_rows(rows)[:-301])
    put("ply: truncated ascii", "cut_ascii.ply", _ply_header(50, fmt="ascii") + b"1 2 3\n")
    put("ply: word for a number", "word.ply", _ply_header(1, fmt="ascii") + b" ".join([b"abc"] * 14) + b"\n")
    put("ply: duplicated property", "dup.ply", _ply_header(2, PLY_PROPS + ["x"]) + b"\0" * 120)
    put("ply: missing properties", "missing_props.ply", _ply_rows(rows[:, :6], PLY_PROPS[:6]))
    put("ply: list where a number belongs", "list.ply",
        _ply_header(1, PLY_PROPS[:-1]).replace(b"end_header", b"property list uchar float rot_3\nend_header")
        + b"\0" * 60)
    put("ply: unknown property type", "type.ply", _ply_header(1, types="quux") + b"\0" * 56)
    put("ply: every value NaN", "nan.ply", _ply_rows(np.full((20, 14), np.nan)))
    put("ply: every position infinite", "inf.ply", _ply_rows(np.where(np.arange(14) < 3, np.inf, rows[:20])))
    put("ply: bad magic", "magic.ply", b"plx\n" + _ply_rows(rows)[4:])
    put("ply: mesh, not splats", "mesh.ply", _ply_header(3, ["x", "y", "z"]).replace(
        b"end_header", b"element face 1\nproperty list uchar int vertex_indices\nend_header")
        + np.zeros(9, "<f4").tobytes() + b"\x03" + np.arange(3, dtype="<i4").tobytes())
    put("compressed ply: huge chunk count", "chunks.ply",
        b"ply\nformat binary_little_endian 1.0\nelement chunk 4000000000\nproperty float min_x\n"
        b"element vertex 1\nproperty uint packed_position\nend_header\n" + b"\0" * 64)

    spz = os.path.join(folder, "good.spz")
    write_spz(spz, scene)
    good_spz = open(spz, "rb").read()
    put("spz: gzip of garbage", "garbage.spz", gzip.compress(b"not an spz file at all" * 10))
    put("spz: truncated gzip", "cut.spz", good_spz[: len(good_spz) // 2])
    put("spz: v4 header with 10^9 points", "v4.spz", struct.pack("<IIIBBBBI12x", 0x5053474E, 4, 10 ** 9, 0, 12, 0, 5, 32)
        + b"\0" * 200)
    put("spz: random bytes", "random.spz", rng.integers(0, 256, 500, dtype=np.uint8).tobytes())

    splat = os.path.join(folder, "good.splat")
    write_splat(splat, scene)
    good_splat = open(splat, "rb").read()
    put(".splat: not whole records", "odd.splat", good_splat[:-7])
    rec = np.frombuffer(good_splat, np.uint8).copy().view(np.float32).reshape(-1, 8)
    bad = rec.copy()
    bad[:, 0:3] = np.nan
    put(".splat: every position NaN", "nan.splat", bad.tobytes())
    bad = rec.copy()
    bad[:, 3] = -1.0
    put(".splat: negative scales", "neg.splat", bad.tobytes())

    sog = os.path.join(folder, "good.sog")
    write_sog(sog, good_scene(64))
    with zipfile.ZipFile(sog) as z:
        members = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(members["meta.json"])
    put("sog: no meta.json", "nometa.sog", _zip({k: v for k, v in members.items() if k != "meta.json"}))
    put("sog: meta.json not JSON", "notjson.sog", _zip({**members, "meta.json": b"{not json"}))
    put("sog: negative count", "count.sog", _zip({**members, "meta.json": json.dumps({**meta, "count": -3}).encode()}))
    put("sog: count larger than the images", "toomany.sog",
        _zip({**members, "meta.json": json.dumps({**meta, "count": 10 ** 6}).encode()}))
    put("sog: image is not WebP", "notwebp.sog", _zip({**members, "means_l.webp": b"RIFF0000WEBPjunk" * 4}))
    put("sog: version 1", "v1.sog", _zip({**members, "meta.json": json.dumps(
        {k: v for k, v in meta.items() if k != "version"}).encode()}))
    put("sog: NaN codebook", "nanbook.sog", _zip({**members, "meta.json": json.dumps(
        {**meta, "scales": {**meta["scales"], "codebook": [float("nan")] * 256}}).encode()}))
    put("sog: truncated zip", "cut.sog", open(sog, "rb").read()[:300])
    sog_dir = os.path.join(folder, "sogdir")
    os.makedirs(sog_dir, exist_ok=True)
    with open(os.path.join(sog_dir, "meta.json"), "wb") as f:
        f.write(members["meta.json"])  # images missing
    cases["sog: folder without its images"] = ("sogdir", None)

    glb = os.path.join(folder, "good.glb")
    write_glb(glb, scene)
    doc, binary = _glb_parts(glb)
    put("glb: bad magic", "magic.glb", b"gLTf" + open(glb, "rb").read()[4:])
    put("glb: truncated", "cut.glb", open(glb, "rb").read()[:-100])
    big = json.loads(json.dumps(doc))
    big["accessors"][0]["count"] = 10 ** 9
    put("glb: accessor count past its buffer", "count.glb", _glb(big, binary))
    plain = json.loads(json.dumps(doc))
    del plain["meshes"][0]["primitives"][0]["extensions"]
    put("glb: no KHR_gaussian_splatting", "plain.glb", _glb(plain, binary))
    nan_bin = bytearray(binary)
    pos_view = doc["bufferViews"][doc["accessors"][0]["bufferView"]]
    nan_bin[pos_view["byteOffset"]:pos_view["byteOffset"] + pos_view["byteLength"]] = \
        np.full(pos_view["byteLength"] // 4, np.nan, "<f4").tobytes()
    put("glb: every position NaN", "nan.glb", _glb(doc, bytes(nan_bin)))
    op_bin = bytearray(binary)
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    op_view = doc["bufferViews"][doc["accessors"][attrs["KHR_gaussian_splatting:OPACITY"]]["bufferView"]]
    op_bin[op_view["byteOffset"]:op_view["byteOffset"] + op_view["byteLength"]] = \
        np.full(op_view["byteLength"] // 4, 3.0, "<f4").tobytes()
    put("glb: opacity outside 0-1", "opacity.glb", _glb(doc, bytes(op_bin)))
    put("glb: unknown required extension", "required.glb", _glb({**doc, "extensionsRequired": ["EXT_meshopt_compression"]},
                                                                binary))
    put("gltf: JSON with a missing .bin", "missing_bin.gltf", json.dumps(
        {**doc, "buffers": [{"byteLength": len(binary), "uri": "nowhere.bin"}]}).encode())

    ks = os.path.join(folder, "good.ksplat")
    write_ksplat(ks, scene)
    good_ks = bytearray(open(ks, "rb").read())
    put("ksplat: smaller than its header", "small.ksplat", bytes(good_ks[:1000]))
    many = bytearray(good_ks)
    struct.pack_into("<I", many, 4, 10 ** 6)
    put("ksplat: 10^6 sections claimed", "sections.ksplat", bytes(many))
    count = bytearray(good_ks)
    struct.pack_into("<I", count, 4096, 10 ** 8)
    put("ksplat: section count past the data", "count.ksplat", bytes(count))
    mode = bytearray(good_ks)
    struct.pack_into("<H", mode, 20, 9)
    put("ksplat: unknown compression mode", "mode.ksplat", bytes(mode))

    out = []
    for name, (filename, data) in cases.items():
        path = os.path.join(folder, filename)
        if data is not None:
            with open(path, "wb") as f:
                f.write(data)
        out.append((name, path))
    os.makedirs(os.path.join(folder, "folder.ply"), exist_ok=True)
    out.append(("a folder named .ply", os.path.join(folder, "folder.ply")))
    for name in ("good.spz", "good.splat", "good.sog", "good.glb", "good.ksplat"):
        os.unlink(os.path.join(folder, name))
    return out


def command_cases(folder: str) -> list[tuple[str, list[str]]]:
    """Bad options and outputs for every command, on a good small scene: (case name, argv)."""
    os.makedirs(folder, exist_ok=True)
    ply = os.path.join(folder, "good.ply")
    write_ply(ply, good_scene())
    out = os.path.join(folder, "out")
    a_file = os.path.join(folder, "a_file.txt")
    with open(a_file, "w") as f:
        f.write("not a folder")
    os.makedirs(os.path.join(folder, "dir.spz"), exist_ok=True)
    foreign = os.path.join(folder, "foreign")
    os.makedirs(foreign, exist_ok=True)
    open(os.path.join(foreign, "radiance.exr"), "wb").close()  # ours by name, but no probe.json vouches for it
    bake = ["bake", ply, "--out", out]
    render = ["render", ply, "--camera", "0", "0", "0", "--look-at", "1", "0", "0", "--out",
              os.path.join(folder, "v.exr")]
    cube = ["cubemap", ply, "--probe", "0", "0", "0", "--out", os.path.join(folder, "cube")]
    return [
        ("bake --probe nan", bake + ["--probe", "nan", "0", "1"]),
        ("bake --probe inf", bake + ["--probe", "0", "inf", "1"]),
        ("bake --probe two numbers", bake + ["--probe", "0", "1"]),
        ("bake --face-size 100000", bake + ["--face-size", "100000"]),
        ("bake --irradiance-size 100000", bake + ["--irradiance-size", "100000"]),
        ("bake --face-size -1", bake + ["--face-size", "-1"]),
        ("bake --face-size abc", bake + ["--face-size", "abc"]),
        ("bake --face-size 2.5", bake + ["--face-size", "2.5"]),
        ("bake --irradiance-size -1", bake + ["--irradiance-size", "-1"]),
        ("bake --tolerance 0", bake + ["--tolerance", "0"]),
        ("bake --tolerance 2", bake + ["--tolerance", "2"]),
        ("bake --tolerance nan", bake + ["--tolerance", "nan"]),
        ("bake --method bogus", bake + ["--method", "bogus"]),
        ("bake --out is a file", ["bake", ply, "--out", a_file]),
        ("bake --out under a file", ["bake", ply, "--out", os.path.join(a_file, "probe")]),
        ("bake --out on a read-only file system", ["bake", ply, "--out", "/proc/gs-ibl-probe"]),
        ("bake --out holds files no probe.json vouches for", ["bake", ply, "--out", foreign]),
        ("bake --preview in a missing folder", bake + ["--preview", os.path.join(folder, "nope", "p.png")]),
        ("bake --preview not a .png", bake + ["--preview", os.path.join(folder, "p.txt")]),
        ("bake --preview is a folder", bake + ["--preview", folder]),
        ("bake on a missing file", ["bake", os.path.join(folder, "nope.ply"), "--out", out]),
        ("render --fov 0", render + ["--fov", "0"]),
        ("render --fov 180", render + ["--fov", "180"]),
        ("render --fov nan", render + ["--fov", "nan"]),
        ("render --size 0 48", render + ["--size", "0", "48"]),
        ("render --size 100000 100000", render + ["--size", "100000", "100000"]),
        ("render --exposure inf", render + ["--exposure", "inf"]),
        ("render --camera nan", ["render", ply, "--camera", "nan", "0", "0", "--look-at", "1", "0", "0",
                                 "--out", os.path.join(folder, "v.exr")]),
        ("render camera = look-at", ["render", ply, "--camera", "1", "0", "0", "--look-at", "1", "0", "0",
                                     "--out", os.path.join(folder, "v.exr")]),
        ("render --up along the view", render + ["--up", "1", "0", "0"]),
        ("render --out not .exr", ["render", ply, "--camera", "0", "0", "0", "--look-at", "1", "0", "0",
                                   "--out", os.path.join(folder, "v.txt")]),
        ("render --png in a missing folder", render + ["--png", os.path.join(folder, "nope", "v.png")]),
        ("cubemap --face-size 100000", cube + ["--face-size", "100000"]),
        ("cubemap --face-size 0", cube + ["--face-size", "0"]),
        ("cubemap --probe nan", ["cubemap", ply, "--probe", "nan", "0", "0", "--out", os.path.join(folder, "c")]),
        ("convert to an unknown format", ["convert", ply, os.path.join(folder, "x.obj")]),
        ("convert into a missing folder", ["convert", ply, os.path.join(folder, "nope", "x.spz")]),
        ("convert onto a folder", ["convert", ply, os.path.join(folder, "dir.spz")]),
        ("convert from a folder", ["convert", folder, os.path.join(folder, "x.spz")]),
        ("sample onto a read-only file system", ["sample", "/proc/gs-ibl-room.ply"]),
    ]
