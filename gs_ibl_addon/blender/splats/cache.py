"""One GPU copy of each splat object, shared by the viewport overlay and probe bakes.

Reading a splat object (``read_steps`` on the main thread, ``to_world`` and ``SplatRenderer`` on a worker: a job,
blender/jobs.py) costs about as much as a small bake, and a scene on the GPU twice costs twice the memory, so both are
done once per object and reused until the
object changes: the entry's key is the object's geometry, our mesh or a native splat Point Cloud alike (identity,
point count, a generation bumped by every geometry edit of it, seen by a depsgraph handler) and its world matrix.
The object's colour space is not part of the key: it is a push constant of the renderer, set on every get().
Entries of deleted objects are dropped at the next depsgraph update; everything is freed when a file is loaded
and when the extension is disabled. Renderers stay on the GPU between bakes (that is what makes "Update When
Moved" cheap).

Several splat objects that light one probe together (a room and a capture inside it: lighting/sources.py) get an
entry of their own (``set_steps``): one GPU copy of all of them, merged and sorted together, kept while none of them
changes, dropped when one is deleted or when a bake from the same first object asks for another set.

Next to the GPU copy an entry keeps a slim host copy (``host``: positions, scales, rotations, opacities and the
base colour, 56 bytes a splat, 56 MB for 1M splats; the higher SH bands, up to 180 bytes more, are not kept): the
near-splats check (core/probe/near.py) reads it, so a bake from the cache warns of a probe inside the splats
without reading the object again.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..common import handlers
from ..common.jobs import Job, Progress, Step, Work, busy, cancel_all, gpu, run_now
from .object import colour_space_of, merged_world, read_steps, splat_count, to_world

# What a splat object's data can be: a change to one of these is a geometry edit (PointCloud: Blender 5.3 splats).
_GEOMETRY = tuple(t for t in (bpy.types.Mesh, getattr(bpy.types, "PointCloud", None)) if t is not None)


@dataclass
class CachedSplats:
    key: tuple
    renderer: object  # core.render.renderer.SplatRenderer holding the object's splats in world space (no full
    # CPU copy is kept, which for millions of splats would double what Blender's mesh already holds)
    host: object = None  # core.scene.SplatScene without the higher SH bands: bake_probe's host_splats
    timings: dict = field(default_factory=dict)  # wall s of making it: reading, turning SH, upload (bake reports)


def slim(scene):
    """``scene`` with only the base colour of its SH (what near_splats reads)."""
    return replace(scene, sh=scene.sh[:, :1].copy())


_entries: dict[int | tuple, CachedSplats] = {}  # uid(object) -> entry; ("set", uid, uid, ...) -> a set's
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


def get_steps(obj: bpy.types.Object, wait_for_upload: bool = True) -> Job:
    """A job (blender/jobs.py) giving the object's splats in world space and on the GPU: read on the main thread
    an attribute at a time, turned into world space and uploaded by a worker, on first use or after a change.

    With ``wait_for_upload``, a running overlay upload of the object (Show Splats) is waited for rather than
    the object read twice (the upload job itself passes False). Raises ValueError naming the object when it cannot
    be read (e.g. non-uniform scale).
    """
    global uploads
    key = data_key(obj)
    object_uid, mesh_uid, name = uid(obj), uid(obj.data), obj.name
    uploading = busy(upload_key(obj)) if wait_for_upload else None
    while uploading is not None and not uploading.done:
        yield Step(f"waiting for the upload of {name}", wait_for=uploading)
    entry = _entries.get(object_uid)
    if entry is None or entry.key != key:
        t = time.perf_counter()
        local, matrix = yield from read_steps(obj)
        digest = fingerprint_of(local.positions)
        reading = time.perf_counter() - t
        entry = yield Work(_build, key, local, matrix, name)
        entry.timings = {"reading": reading, **entry.timings}
        # The object may be gone by now (a Runner's job lets the user work meanwhile): only uids from here on.
        release(object_uid)
        _entries[object_uid] = entry
        _fingerprints[mesh_uid] = digest
        uploads += 1
        space = local.colour_space
    else:
        space = colour_space_of(obj)
    entry.renderer.colour_space = space  # the colour rule: nothing uploaded again when it changes
    if entry.host.colour_space != space:  # the host copy is the scene as rendered
        entry.host = replace(entry.host, colour_space=space)
    return entry


def _build(key: tuple, local, matrix: np.ndarray, name: str, progress: Progress) -> CachedSplats:
    """The worker's part of get_steps: SH turned with the object, the splats uploaded."""
    from ...core.render.renderer import SplatRenderer  # Vulkan is loaded only when splats are first drawn or baked
    progress(f"turning {local.count:,} splats of {name!r} into world space", 0.0)
    t0 = time.perf_counter()
    scene = to_world(local, matrix, name)
    del local
    progress(f"uploading {scene.count:,} splats of {name!r}", 0.5)
    t1 = time.perf_counter()
    entry = CachedSplats(key, SplatRenderer(scene), slim(scene))
    entry.timings = {"turning SH": t1 - t0, "upload": time.perf_counter() - t1}
    progress(f"uploaded {scene.count:,} splats", 1.0)
    return entry  # the higher SH bands go with ``scene``


def set_steps(objs: list[bpy.types.Object]) -> Job:
    """get_steps for the splat objects that light one probe together (``objs``): one object's own entry, or one
    entry holding all of them in world space, merged (splats.object.merged_world: a mix of colour spaces re-encoded
    for Blender's rule, so each one's colour space is part of the key), read and uploaded again only when one of them
    changed."""
    set_uid = ("set",) + tuple(uid(o) for o in objs)
    # one set per probe's own object at a time: a set it lit with before (another member hidden or shown since)
    # gives its GPU copy back
    for old in [k for k in _entries if isinstance(k, tuple) and k[1] == set_uid[1] and k != set_uid]:
        release(old)
    if len(objs) == 1:
        return (yield from get_steps(objs[0]))
    global uploads
    key = tuple((data_key(o), colour_space_of(o)) for o in objs)
    entry = _entries.get(set_uid)
    if entry is None or entry.key != key:
        t = time.perf_counter()
        parts = []
        for o in objs:
            yield Step(f"reading {o.name}", None)
            parts.append((*(yield from read_steps(o)), o.name))
        reading = time.perf_counter() - t
        entry = yield Work(_build_set, key, parts)
        entry.timings = {"reading": reading, **entry.timings}
        release(set_uid)
        _entries[set_uid] = entry
        uploads += 1
    return entry  # (its renderer's colour rule is the merged scene's, set when it was made)


def _build_set(key: tuple, parts: list, progress: Progress) -> CachedSplats:
    """The worker's part of set_steps: each object's splats into world space, merged, uploaded."""
    from ...core.render.renderer import SplatRenderer
    progress(f"merging {len(parts)} splat objects in world space", 0.0)
    t0 = time.perf_counter()
    scene = merged_world(parts)
    del parts
    progress(f"uploading {scene.count:,} splats", 0.5)
    t1 = time.perf_counter()
    entry = CachedSplats(key, SplatRenderer(scene), slim(scene))
    entry.timings = {"turning SH": t1 - t0, "upload": time.perf_counter() - t1}
    return entry


def _members(key: int | tuple) -> set:
    """The objects (uids) an entry holds."""
    return set(key[1:]) if isinstance(key, tuple) else {key}


def upload_key(obj: bpy.types.Object) -> str:
    """The key (blender/jobs.py start) of the background job that uploads ``obj``'s splats for the overlay."""
    return f"upload:{uid(obj)}"


def get(obj: bpy.types.Object) -> CachedSplats:
    """get_steps, run now."""
    return run_now(get_steps(obj))


def current(obj: bpy.types.Object) -> CachedSplats | None:
    """The object's entry if it holds the object as it is now (nothing read or uploaded), else None."""
    entry = _entries.get(uid(obj))
    return entry if entry is not None and entry.key == data_key(obj) else None


def fingerprint_of(positions: np.ndarray) -> bytes:
    """A digest of splat positions as Blender stores them (float32, (n, 3))."""
    import hashlib
    buf = np.ascontiguousarray(positions, np.float32)
    return hashlib.blake2b(buf.tobytes(), digest_size=16, person=len(buf).to_bytes(8, "little")).digest()


def fingerprint(data) -> bytes:
    """A digest of a splat object's geometry (point count and positions, ~50 ms for 3M): tells an undo that put
    back the same splats (Blender reports every restored mesh as updated) from one that undid an edit."""
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
    return fingerprint_of(buf.reshape(n, 3))


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
        _close_when_free(entry.renderer)


_closing: list = []  # renderers dropped while a job's worker held the GPU (it may be rendering with them)


def _close_when_free(renderer=None) -> float | None:
    """Close ``renderer`` (and any left waiting) now if no worker holds the GPU, else from a timer once none does;
    the main thread never waits for a worker here (a depsgraph update would freeze the UI for a whole bake)."""
    if renderer is not None:
        _closing.append(renderer)
    if not gpu.acquire(blocking=False):
        if renderer is not None and len(_closing) == 1:
            bpy.app.timers.register(_close_when_free, first_interval=0.25)
        return 0.25
    try:
        while _closing:
            _closing.pop().close()
    finally:
        gpu.release()
    return None


def clear() -> None:
    cancel_all()  # jobs' workers may be using these renderers: stop them, then wait for the GPU
    with gpu:
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
        for gone in [k for k in _entries if not _members(k) <= live]:
            release(gone)


@persistent
def on_load_pre(*_args) -> None:
    clear()


_HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("load_pre", on_load_pre))


def register_handlers() -> None:
    handlers.add(_HANDLERS)


def unregister_handlers() -> None:
    handlers.remove(_HANDLERS)
    clear()
