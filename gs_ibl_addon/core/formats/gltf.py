"""glTF 2.0 (``.glb`` and ``.gltf``) point primitives with the ratified ``KHR_gaussian_splatting`` extension.

Attributes read (the extension's README, KhronosGroup/glTF): ``POSITION``; ``KHR_gaussian_splatting:ROTATION``
(unit quaternion x, y, z, w: float, or normalized signed byte/short); ``:SCALE`` (log scale: float, signed
byte/short, normalized or not); ``:OPACITY`` (0-1: float, or normalized unsigned byte/short);
``:SH_DEGREE_0_COEF_0`` and ``:SH_DEGREE_l_COEF_n`` (float VEC3, r g b), or, lacking SH, ``COLOR_0`` (its RGB is
the diffuse colour). SPZ-compressed primitives (``KHR_gaussian_splatting_compression_spz_2``: a buffer view
holding an SPZ file) are decoded by formats/spz.py. Node transforms (matrix or TRS; rotation and uniform scale
only) are applied; every splat primitive of the default scene is kept, in order.

Two conventions the spec leaves to writers, taken from PlayCanvas splat-transform (the ecosystem's converter):
  * axes: glTF is y-up; 3DGS PLY data (SplatScene) is y-down. splat-transform turns PLY data 180 degrees about
    z to write glTF, and so we turn it back (x and y negated); the other common choice (about x) differs from
    this by a half turn about the vertical axis only;
  * scale: splat-transform (2.x and 3.x) writes SCALE as exp(log scale), i.e. linear, against the spec's log
    space; a file whose ``asset.generator`` starts with "splat-transform" is read as linear.
``write_glb`` follows the spec (log scales, float attributes, COLOR_0 for viewers without splat support).
"""
from __future__ import annotations

import base64
import json
import os
import struct
from functools import partial

import numpy as np

from ..scene import SH_C0, SplatScene, quat_multiply
from .checks import check_input, fail
from .repair import clamp_scales, new_counts, normalise_quaternions, reported

EXT = "KHR_gaussian_splatting"
SPZ_EXT = "KHR_gaussian_splatting_compression_spz_2"
_P = EXT + ":"
_REEXPORT = "re-export it with a glTF writer that supports KHR_gaussian_splatting"
_fail = partial(fail, todo=_REEXPORT)
_COMPONENTS = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_NORM = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_FLIP = np.array([-1.0, -1.0, 1.0])  # glTF axes <-> SplatScene (PLY) axes, a half turn about z: see above
_HALF_TURN_Z = np.array([0.0, 0.0, 0.0, 1.0])  # that turn as a quaternion (w, x, y, z); its own inverse up to sign


def _turn(positions: np.ndarray, wxyz: np.ndarray, sh_rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Turn splats half about z (both directions: it is its own inverse). The turn multiplies each splat's
    rotation from the left (so a splat's quaternion comes back exactly as the writer had it); each SH basis
    function is even or odd under it (formats/spz.py's sign rule, applied to the SH only)."""
    from .spz import _flip
    _flip(np.zeros((0, 3), np.float32), np.zeros((0, 4), np.float32), sh_rest, _FLIP)
    q = quat_multiply(_HALF_TURN_Z, wxyz.astype(np.float64))
    return (positions.astype(np.float64) * _FLIP).astype(np.float32), q.astype(np.float32)


_SH_PER_DEGREE = (1, 3, 5, 7)
_GLB_JSON, _GLB_BIN = 0x4E4F534A, 0x004E4942


def _load(path: str) -> tuple[dict, bytes | None]:
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"glTF":
        try:
            return json.loads(data.decode("utf-8")), None
        except (UnicodeDecodeError, ValueError) as e:
            raise _fail(path, f"neither a binary glTF (no 'glTF' magic) nor glTF JSON ({e})") from None
    if len(data) < 20:
        raise _fail(path, f"only {len(data)} bytes: a .glb header and its JSON chunk need more; truncated")
    _magic, version, length = struct.unpack_from("<4sII", data)
    if version != 2:
        raise _fail(path, f"glTF binary version {version}; glTF 2.0 files have version 2")
    if length != len(data):
        raise _fail(path, f"the header says {length:,} bytes but the file has {len(data):,}: truncated or damaged")
    at, doc, binary = 12, None, None
    data = memoryview(data)  # chunks are views: the binary chunk is not copied
    while at + 8 <= len(data):
        size, kind = struct.unpack_from("<II", data, at)
        if at + 8 + size > len(data):
            raise _fail(path, f"a chunk at byte {at} claims {size:,} bytes, past the end of the file: truncated")
        body = data[at + 8:at + 8 + size]
        if kind == _GLB_JSON and doc is None:
            try:
                doc = json.loads(bytes(body).decode("utf-8"))
            except (UnicodeDecodeError, ValueError) as e:
                raise _fail(path, f"the JSON chunk is not valid JSON ({e})") from None
        elif kind == _GLB_BIN and binary is None:
            binary = body
        at += 8 + size
    if not isinstance(doc, dict):
        raise _fail(path, "no JSON chunk holding a glTF object")
    return doc, binary


class _Doc:
    """Typed access to the glTF JSON with one clear error for anything missing or out of range."""

    def __init__(self, path: str, doc: dict, binary: bytes | None) -> None:
        self.path, self.doc, self.binary = path, doc, binary
        self._buffers: dict[int, bytes] = {}

    def item(self, kind: str, index) -> dict:
        items = self.doc.get(kind)
        if isinstance(index, bool) or not isinstance(index, int) or not isinstance(items, list) \
                or not 0 <= index < len(items) or not isinstance(items[index], dict):
            raise _fail(self.path, f"refers to {kind}[{index!r}], which does not exist")
        return items[index]

    def buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            b = self.item("buffers", index)
            uri = b.get("uri")
            if uri is None:
                if self.binary is None:
                    raise _fail(self.path, f"buffers[{index}] has no uri and the file has no binary chunk")
                data = self.binary
            elif isinstance(uri, str) and uri.startswith("data:"):
                try:
                    data = base64.b64decode(uri.split(",", 1)[1], validate=True)
                except (IndexError, ValueError) as e:
                    raise _fail(self.path, f"buffers[{index}] has a bad data: uri ({e})") from None
            elif isinstance(uri, str):
                full = os.path.join(os.path.dirname(os.path.abspath(self.path)), uri)
                if not os.path.isfile(full):
                    raise fail(self.path, f"buffers[{index}] names the file '{uri}', which is missing",
                               "keep the .bin file beside the .gltf, or use the .glb")
                with open(full, "rb") as f:
                    data = f.read()
            else:
                raise _fail(self.path, f"buffers[{index}].uri is not a string")
            declared = b.get("byteLength")
            if not isinstance(declared, int) or declared > len(data):
                raise _fail(self.path, f"buffers[{index}] declares {declared!r} bytes but holds {len(data):,}: "
                                       "truncated")
            self._buffers[index] = data
        return self._buffers[index]

    def view(self, index: int) -> tuple[bytes, int, int, int | None]:
        v = self.item("bufferViews", index)
        data = self.buffer(v.get("buffer"))
        offset, length, stride = v.get("byteOffset", 0), v.get("byteLength"), v.get("byteStride")
        if not all(isinstance(x, int) and x >= 0 for x in (offset, length)) or offset + length > len(data):
            raise _fail(self.path, f"bufferViews[{index}] (offset {offset!r}, length {length!r}) lies outside "
                                   f"its {len(data):,}-byte buffer: truncated or damaged")
        if stride is not None and (not isinstance(stride, int) or not 4 <= stride <= 252):
            raise _fail(self.path, f"bufferViews[{index}].byteStride {stride!r} is not 4-252")
        return data, offset, length, stride

    def accessor(self, index, name: str, n: int | None, types: tuple[str, ...], components: tuple[int, ...]
                 ) -> np.ndarray:
        """The accessor's values as float32 (n, width), normalized integers mapped to [0, 1] or [-1, 1]."""
        a = self.item("accessors", index)
        kind, comp, count = a.get("type"), a.get("componentType"), a.get("count")
        if kind not in types or comp not in components:
            raise _fail(self.path, f"attribute {name} is {kind} of component type {comp}; the extension allows "
                                   f"{'/'.join(types)} of {', '.join(_COMPONENTS.get(c, str(c)) for c in components)}")
        if not isinstance(count, int) or count <= 0 or (n is not None and count != n):
            raise _fail(self.path, f"attribute {name} holds {count!r} values, expected {n if n else 'at least 1'}")
        if "sparse" in a or "bufferView" not in a:
            raise _fail(self.path, f"attribute {name} is a sparse or empty accessor, which splats do not use")
        data, start, length, stride = self.view(a["bufferView"])
        width, dtype = _WIDTH[kind], np.dtype(_COMPONENTS[comp])
        elem = width * dtype.itemsize
        stride = stride or elem
        offset = a.get("byteOffset", 0)
        if not isinstance(offset, int) or offset < 0 or offset + stride * (count - 1) + elem > length:
            raise _fail(self.path, f"attribute {name}: {count:,} values (stride {stride}) do not fit in their "
                                   f"{length:,}-byte buffer view: truncated or damaged")
        raw = np.ndarray((count, width), dtype, data, start + offset, (stride, dtype.itemsize))
        values = raw.astype(np.float32)
        if a.get("normalized") and comp in _NORM:
            values = np.maximum(values / np.float32(_NORM[comp]), np.float32(-1.0))
        return values


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T  # glTF stores column-major
    t = np.asarray(node.get("translation", (0, 0, 0)), np.float64)
    x, y, z, w = np.asarray(node.get("rotation", (0, 0, 0, 1)), np.float64)
    s = np.asarray(node.get("scale", (1, 1, 1)), np.float64)
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def _splat_primitives(g: _Doc) -> list[tuple[dict, np.ndarray]]:
    """(primitive, world matrix) for every splat primitive reachable from the default scene, in order."""
    doc, found = g.doc, []
    scenes = doc.get("scenes")
    if isinstance(scenes, list) and scenes:
        roots = g.item("scenes", doc.get("scene", 0)).get("nodes", [])
    else:
        roots = list(range(len(doc.get("nodes", []) or [])))
    stack = [(r, np.eye(4), 0) for r in reversed(roots)]
    while stack:
        index, parent, depth = stack.pop()
        if depth > 64:
            raise _fail(g.path, "the node hierarchy is deeper than 64 levels (a cycle?): damaged")
        node = g.item("nodes", index)
        try:
            world = parent @ _node_matrix(node)
        except (TypeError, ValueError):
            raise _fail(g.path, f"nodes[{index}] has a malformed matrix/translation/rotation/scale") from None
        if "mesh" in node:
            for p in g.item("meshes", node["mesh"]).get("primitives", []):
                if isinstance(p, dict) and EXT in (p.get("extensions") or {}):
                    found.append((p, world))
        stack += [(c, world, depth + 1) for c in reversed(node.get("children", []))]
    return found


def read_gltf(path: str | os.PathLike) -> SplatScene:
    """Every KHR_gaussian_splatting primitive of a .glb/.gltf's default scene, as one SplatScene."""
    path = check_input(path)
    doc, binary = _load(path)
    version = str((doc.get("asset") or {}).get("version", ""))
    if not version.startswith("2."):
        raise _fail(path, f"asset.version is {version or 'missing'}; this reader handles glTF 2.0")
    g = _Doc(path, doc, binary)
    known = {EXT, SPZ_EXT, "KHR_mesh_quantization"}
    unknown = [e for e in doc.get("extensionsRequired", []) or [] if e not in known]
    if unknown:
        raise fail(path, f"requires the glTF extension(s) {', '.join(map(str, unknown))}, which this reader does "
                         "not decode", "export it without them (e.g. without meshopt compression)")
    prims = _splat_primitives(g)
    if not prims:
        raise fail(path, f"no point primitive with the {EXT} extension: this glTF holds no Gaussian splats",
                   "import it with File > Import > glTF instead, or export the splats with KHR_gaussian_splatting")
    linear = str((doc.get("asset") or {}).get("generator", "")).lower().startswith("splat-transform")
    parts = [_primitive(g, p, linear) for p, _ in prims]
    parts = [s if np.allclose(m, np.eye(4)) else s.transformed(_scene_matrix(m)) for s, (_, m) in zip(parts, prims)]
    degree = max(s.sh_degree for s in parts)
    parts = [s.with_sh_degree(degree) for s in parts]
    repairs: dict[str, int] = {}
    for s in parts:
        for k, v in s.repairs.items():
            repairs[k] = repairs.get(k, 0) + v
    return SplatScene(*(np.concatenate([getattr(s, f) for s in parts]) for f in
                        ("positions", "scales", "rotations", "opacities", "sh")), source=path, repairs=repairs)


def _scene_matrix(m: np.ndarray) -> np.ndarray:
    """A glTF-space transform as the same transform in SplatScene axes."""
    f = np.diag(np.append(_FLIP, 1.0))
    return f @ m @ f


def _primitive(g: _Doc, prim: dict, linear_scale: bool) -> SplatScene:
    ext = prim["extensions"][EXT] or {}
    spz = (ext.get("extensions") or {}).get(SPZ_EXT) if isinstance(ext, dict) else None
    if spz is not None:
        return _spz_primitive(g, spz)
    attrs = prim.get("attributes") or {}
    for name in ("POSITION", _P + "ROTATION", _P + "SCALE", _P + "OPACITY"):
        if name not in attrs:
            raise _fail(g.path, f"a splat primitive lacks the required attribute {name}")
    pos = g.accessor(attrs["POSITION"], "POSITION", None, ("VEC3",), (5126, 5120, 5121, 5122, 5123))
    n = len(pos)
    rot = g.accessor(attrs[_P + "ROTATION"], "ROTATION", n, ("VEC4",), (5126, 5120, 5122))
    scale = g.accessor(attrs[_P + "SCALE"], "SCALE", n, ("VEC3",), (5126, 5120, 5122))
    opacity = g.accessor(attrs[_P + "OPACITY"], "OPACITY", n, ("SCALAR",), (5126, 5121, 5123))[:, 0]
    degree = 0
    while degree < 3 and all(f"{_P}SH_DEGREE_{degree + 1}_COEF_{c}" in attrs
                             for c in range(_SH_PER_DEGREE[degree + 1])):
        degree += 1
    sh = np.zeros((n, (degree + 1) ** 2, 3), np.float32)
    if _P + "SH_DEGREE_0_COEF_0" in attrs:
        k = 0
        for d in range(degree + 1):
            for c in range(_SH_PER_DEGREE[d]):
                name = f"{_P}SH_DEGREE_{d}_COEF_{c}"
                sh[:, k] = g.accessor(attrs[name], name.split(":")[1], n, ("VEC3",), (5126,))
                k += 1
    elif "COLOR_0" in attrs:
        colour = g.accessor(attrs["COLOR_0"], "COLOR_0", n, ("VEC3", "VEC4"), (5126, 5121, 5123))
        sh[:, 0] = (colour[:, :3] - np.float32(0.5)) / np.float32(SH_C0)
    else:
        raise _fail(g.path, f"a splat primitive has neither {_P}SH_DEGREE_0_COEF_0 nor COLOR_0: no colour")

    counts = new_counts()
    with np.errstate(over="ignore", invalid="ignore"):
        scales = scale if linear_scale else np.exp(scale)
    finite = (np.isfinite(pos).all(1) & np.isfinite(rot).all(1) & np.isfinite(scales).all(1)
              & np.isfinite(opacity) & np.isfinite(sh).all((1, 2)))
    if linear_scale:
        finite &= (scales > 0).all(1)
    if not finite.any():
        raise _fail(g.path, f"all {n} splats have NaN, infinite or (linear) non-positive values: damaged")
    counts["dropped_nonfinite"] = int(n - finite.sum())
    pos, rot, scales, opacity, sh = pos[finite], rot[finite], scales[finite], opacity[finite], sh[finite]
    if ((opacity < 0) | (opacity > 1)).any():
        raise _fail(g.path, f"{int(((opacity < 0) | (opacity > 1)).sum())} opacities lie outside 0-1, which the "
                            "extension forbids (logit values written by mistake?)")
    scales32 = np.ascontiguousarray(scales, np.float32)
    clamp_scales(scales32, counts)
    wxyz = normalise_quaternions(rot[:, [3, 0, 1, 2]].astype(np.float32), counts)
    rest = sh[:, 1:]  # turned in place
    positions, wxyz = _turn(pos, wxyz, rest)
    sh32 = sh
    opacities = np.clip(opacity, 1e-6, 1 - 1e-6).astype(np.float32)
    return SplatScene(positions, scales32, wxyz, opacities, sh32, source=g.path, repairs=reported(counts))


def _spz_primitive(g: _Doc, spz: dict) -> SplatScene:
    import tempfile

    from .spz import read_spz
    data, start, length, _ = g.view(spz.get("bufferView"))
    fd, tmp = tempfile.mkstemp(suffix=".spz")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data[start:start + length])
        try:
            s = read_spz(tmp, coordinates="RDF")  # as stored: the glTF frame, turned below like any glTF data
        except ValueError as e:
            raise _fail(g.path, f"its {SPZ_EXT} data: {str(e).replace(tmp, 'SPZ')}") from None
    finally:
        os.unlink(tmp)
    rest = s.sh[:, 1:].copy()
    positions, rotations = _turn(s.positions, s.rotations, rest)
    return SplatScene(positions, s.scales, rotations, s.opacities, np.concatenate([s.sh[:, :1], rest], 1),
                      source=g.path, repairs=s.repairs)


def write_glb(path: str | os.PathLike, scene: SplatScene) -> None:
    """Write ``scene`` as a .glb with KHR_gaussian_splatting (float attributes, log scales, SH to its degree)."""
    path = os.fspath(path)
    n = scene.count
    if n == 0:
        raise ValueError(f"{path}: the scene has no splats to write")
    rest = scene.sh[:, 1:].astype(np.float32).copy()
    positions, rotations = _turn(scene.positions, scene.rotations, rest)
    q = rotations.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rgb = np.clip(0.5 + SH_C0 * scene.sh[:, 0].astype(np.float64), 0, 1)
    colour = np.round(np.concatenate([rgb, scene.opacities[:, None]], 1) * 255).astype(np.uint8)
    attributes = [("POSITION", positions.astype(np.float32), "VEC3", 5126, False),
                  ("COLOR_0", colour, "VEC4", 5121, True),
                  (_P + "ROTATION", q[:, [1, 2, 3, 0]].astype(np.float32), "VEC4", 5126, False),
                  (_P + "SCALE", np.log(scene.scales.astype(np.float64)).astype(np.float32), "VEC3", 5126, False),
                  (_P + "OPACITY", scene.opacities.astype(np.float32)[:, None], "SCALAR", 5126, False),
                  (_P + "SH_DEGREE_0_COEF_0", scene.sh[:, 0].astype(np.float32), "VEC3", 5126, False)]
    k = 1
    for d in range(1, scene.sh_degree + 1):
        for c in range(_SH_PER_DEGREE[d]):
            attributes.append((f"{_P}SH_DEGREE_{d}_COEF_{c}", rest[:, k - 1], "VEC3", 5126, False))
            k += 1
    blobs, views, accessors, attrs, at = [], [], [], {}, 0
    for i, (name, values, kind, comp, norm) in enumerate(attributes):
        raw = np.ascontiguousarray(values).tobytes()
        views.append({"buffer": 0, "byteOffset": at, "byteLength": len(raw), "target": 34962})
        acc = {"bufferView": i, "componentType": comp, "count": n, "type": kind}
        if norm:
            acc["normalized"] = True
        if name == "POSITION":
            acc["min"], acc["max"] = values.min(0).tolist(), values.max(0).tolist()
        accessors.append(acc)
        attrs[name] = i
        blobs.append(raw + b"\0" * (-len(raw) % 4))
        at += len(blobs[-1])
    binary = b"".join(blobs)
    doc = {"asset": {"version": "2.0", "generator": "gs-ibl"}, "extensionsUsed": [EXT], "scene": 0,
           "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], "buffers": [{"byteLength": len(binary)}],
           "bufferViews": views, "accessors": accessors,
           "meshes": [{"primitives": [{"attributes": attrs, "mode": 0, "extensions": {EXT: {
               "kernel": "ellipse", "colorSpace": "srgb_rec709_display", "sortingMethod": "cameraDistance",
               "projection": "perspective"}}}]}]}
    text = json.dumps(doc).encode("utf-8")
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<II", len(text), _GLB_JSON) + text)
        f.write(struct.pack("<II", len(binary), _GLB_BIN) + binary)
