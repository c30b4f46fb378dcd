"""One GPU copy of each splat object, shared by the viewport overlay and probe bakes.

Reading a splat object (``scene_from_object``) and uploading it (``SplatRenderer``) cost about as much as a small
bake, and a scene on the GPU twice costs twice the memory, so both are done once per object and reused until the
object changes: the entry's key is the object's geometry, our mesh or a native splat Point Cloud alike (identity,
point count, a generation bumped by every geometry edit of it, seen by a depsgraph handler) and its world matrix.
The object's colour space is not part of the key: it is a push constant of the renderer, set on every get().
Entries of deleted objects are dropped at the next depsgraph update; everything is freed when a file is loaded
and when the extension is disabled. Renderers stay on the GPU between bakes (that is what makes "Update When
Moved" cheap).

Next to the GPU copy an entry keeps a slim host copy (``host``: positions, scales, rotations, opacities and the
base colour, 56 bytes a splat, 56 MB for 1M splats; the higher SH bands, up to 180 bytes more, are not kept): the
near-splats check (core/probe/near.py) reads it, so a bake from the cache warns of a probe inside the splats
without reading the object again.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import bpy
import numpy as np
from bpy.app.handlers import persistent

from .splat_object import colour_space_of, scene_from_object, splat_count

# What a splat object's data can be: a change to one of these is a geometry edit (PointCloud: Blender 5.3 splats).
_GEOMETRY = tuple(t for t in (bpy.types.Mesh, getattr(bpy.types, "PointCloud", None)) if t is not None)


@dataclass
class CachedSplats:
    key: tuple
    renderer: object  # core.render.renderer.SplatRenderer holding the object's splats in world space (no full
    # CPU copy is kept, which for millions of splats would double what Blender's mesh already holds)
    host: object = None  # core.scene.SplatScene without the higher SH bands: bake_probe's host_splats


def slim(scene):
    """``scene`` with only the base colour of its SH (what near_splats reads)."""
    return replace(scene, sh=scene.sh[:, :1].copy())


_entries: dict[int, CachedSplats] = {}  # uid(object) -> entry
_mesh_generation: dict[int, int] = {}  # uid(mesh) -> number of geometry edits seen
_proxy_only: set[int] = set()  # uid(mesh) whose next geometry update only switched the object's point proxy
_fingerprints: dict[int, bytes] = {}  # uid(mesh) -> fingerprint() of what its entry uploaded
_after_undo = False  # the next geometry updates may be an undo putting back what is already uploaded
uploads = 0  # entries built so far (tests and the console see how often the splats were uploaded)


def uid(idb) -> int:
    """A datablock's identity for this session: session_uid (kept across renames), or, in a Blender
    without it, its memory address (changes on undo: at worst one extra upload)."""
    value = getattr(idb, "session_uid", None)
    return value if value is not None else idb.as_pointer()


def data_key(obj: bpy.types.Object) -> tuple:
    """What the uploaded splats depend on: which geometry, its size, its edits and the object's world matrix."""
    mesh = uid(obj.data)
    return (mesh, splat_count(obj), _mesh_generation.get(mesh, 0),
            np.array(obj.matrix_world, np.float64).tobytes())


def get(obj: bpy.types.Object) -> CachedSplats:
    """The object's splats in world space and on the GPU, read and uploaded on first use or after a change.

    Raises ValueError naming the object when it cannot be read (e.g. non-uniform scale).
    """
    global uploads
    key = data_key(obj)
    entry = _entries.get(uid(obj))
    if entry is None or entry.key != key:
        release(uid(obj))
        from ..core.render.renderer import SplatRenderer  # Vulkan is loaded only when splats are first drawn or baked
        scene = scene_from_object(obj)
        entry = CachedSplats(key, SplatRenderer(scene), slim(scene))
        del scene  # the higher SH bands go with it
        _entries[uid(obj)] = entry
        _fingerprints[uid(obj.data)] = fingerprint(obj.data)
        uploads += 1
    entry.renderer.colour_space = colour_space_of(obj)  # the colour rule: nothing uploaded again when it changes
    if entry.host.colour_space != entry.renderer.colour_space:  # the host copy is the scene as rendered
        entry.host = replace(entry.host, colour_space=entry.renderer.colour_space)
    return entry


def fingerprint(data) -> bytes:
    """A digest of a splat object's geometry (point count and positions, ~50 ms for 3M): tells an undo that put
    back the same splats (Blender reports every restored mesh as updated) from one that undid an edit."""
    import hashlib
    if isinstance(data, bpy.types.Mesh):
        co, n = data.vertices, len(data.vertices)
        buf = np.empty(3 * n, np.float32)
        co.foreach_get("co", buf)
    else:  # a native splat Point Cloud
        attr = data.attributes.get("position")
        n = len(data.points)
        buf = np.empty(3 * n, np.float32)
        if attr is not None:
            attr.data.foreach_get("vector", buf)
    return hashlib.blake2b(buf.tobytes(), digest_size=16, person=n.to_bytes(8, "little")).digest()


def undo_restored() -> None:
    """Called after an undo or redo: geometry updates that follow are edits only where the splats differ."""
    global _after_undo
    _after_undo = True


def proxy_switched(obj: bpy.types.Object) -> None:
    """The object's point proxy was switched on or off (a modifier setting, display only): Blender reports that as
    a geometry update of its mesh, which must not count as an edit of the splats."""
    _proxy_only.add(uid(obj.data))


def release(key: int) -> None:
    entry = _entries.pop(key, None)
    if entry is not None:
        entry.renderer.close()


def clear() -> None:
    for key in list(_entries):
        release(key)
    _mesh_generation.clear()
    _fingerprints.clear()


@persistent
def on_depsgraph_update(scene, depsgraph) -> None:
    """Counts geometry edits per mesh (they invalidate its entry) and frees entries of deleted objects."""
    global _after_undo
    for u in depsgraph.updates:
        if u.is_updated_geometry and isinstance(u.id, _GEOMETRY):
            mesh = uid(u.id.original)
            if mesh in _proxy_only:
                continue
            if _after_undo and mesh in _fingerprints and fingerprint(u.id.original) == _fingerprints[mesh]:
                continue  # undo put back the splats already uploaded: no re-read, no re-upload, no re-bake
            _mesh_generation[mesh] = _mesh_generation.get(mesh, 0) + 1
    _proxy_only.clear()  # the switch's update came with this evaluation; later ones are edits again
    _after_undo = False
    if _entries:
        live = {uid(o) for o in bpy.data.objects}
        for gone in [k for k in _entries if k not in live]:
            release(gone)


@persistent
def on_load_pre(*_args) -> None:
    clear()


def register_handlers() -> None:
    if on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(on_depsgraph_update)
    if on_load_pre not in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.append(on_load_pre)


def unregister_handlers() -> None:
    while on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(on_depsgraph_update)
    while on_load_pre in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(on_load_pre)
    clear()
