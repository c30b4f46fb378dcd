"""Lighting "Volume": one light volume over every lit mesh, shared by all of them (issue 37).

After the World probe's bake, the region every lit mesh occupies over the scene's frame range (each mesh's box at
sampled frames, when anything is animated) is handed to the core (core/probe/volume_region.py ``choose_volume``:
a coarse measurement of the light chooses the spacing, within a probe budget), the volume is baked from every
visible splat object (core/probe/volume_bake.py, on a worker), and its two atlases, packed into the file, are read
by the volume group (volume_nodes.py) inside the local-light group (local_light.py) of every lit mesh: the same
insertion into the user's material and the same per-engine emission difference as a per-object probe or a grid,
with H the volume's light at the shading point. A mesh is lit where it stands in every frame and while dragged
(the lookup is all in the shader); one that leaves the volume's box fades to the World probe's light within one
node spacing. Nothing is written into Blender before the worker's bake is done.
"""
from __future__ import annotations

import json

import bpy
import numpy as np

from ...core.probe import volume as pv
from ...core.render.renderer import BAKE_KEEP_SHARE
from . import local_light as ll
from . import volume_nodes as vn
from ..common.datablocks import image_pixels, packed_float_image
from ..common.jobs import Job, Work
from ..splats import cache as splat_cache
from ..splats.object import colour_space_of, splat_count
from .auto_light import AUTO_KEY
from .object_probes import is_lit_mesh, point_coefficients, probe_renderer_steps, world_box
from .sources import lighting_set, require_splats

REPORT_PREFIX = "Light volume: "
MAX_FRAMES = 48  # frames of an animation whose boxes the region covers (evenly over the range, both ends in)
# The volume's probe budget and cube face for a benchmark's trial: None takes the probe's Volume Probes and the
# core's face (volume_bake.DEFAULT_FACE); benchmarks/volume_light_bench.py and auto_light_bench.py set them.
BUDGET: int | None = None
FACE: int | None = None


def _animated(obj: bpy.types.Object) -> bool:
    """Whether ``obj`` (or a parent) has keyframes, drivers or constraints: its box may change with the frame."""
    while obj is not None:
        ad = obj.animation_data
        if (ad is not None and (ad.action is not None or len(ad.drivers) or len(ad.nla_tracks))) or len(
                obj.constraints):
            return True
        obj = obj.parent
    return False


def sampled_frames(scene: bpy.types.Scene) -> list[int]:
    """The frames whose boxes the region covers: up to MAX_FRAMES over the scene's range, both ends included."""
    a, b = int(scene.frame_start), int(scene.frame_end)
    if b <= a:
        return [a]
    return sorted({int(round(f)) for f in np.linspace(a, b, min(MAX_FRAMES, b - a + 1))})


def _box_of(objects: list[bpy.types.Object]) -> tuple[np.ndarray, np.ndarray]:
    boxes = [world_box(o) for o in objects]
    return np.min([b[0] for b in boxes], 0), np.max([b[1] for b in boxes], 0)


def volume_boxes(scene: bpy.types.Scene, splats: list[bpy.types.Object]):
    """(lit mesh names, one (lo, hi) box per lit mesh and sampled frame, the splats' box, names of the meshes
    outside it): a mesh is lit when its box centre lies inside the splats' box in any sampled frame. The scene is
    put back on its frame."""
    meshes = [o for o in scene.objects if is_lit_mesh(o)]
    frames = sampled_frames(scene) if any(_animated(o) for o in meshes + splats) else [scene.frame_current]
    current, sub = scene.frame_current, scene.frame_subframe
    boxes: dict[str, list] = {o.name: [] for o in meshes}
    lit: set[str] = set()
    within = None
    try:
        for f in frames:
            if len(frames) > 1:
                scene.frame_set(f)
            slo, shi = _box_of(splats)
            within = (slo, shi) if within is None else (np.minimum(within[0], slo), np.maximum(within[1], shi))
            for o in meshes:
                lo, hi = world_box(o)
                boxes[o.name].append((lo, hi))
                c = 0.5 * (lo + hi)
                if np.all(c >= slo) and np.all(c <= shi):
                    lit.add(o.name)
    finally:
        if len(frames) > 1:
            scene.frame_set(current, subframe=sub)
    names = [o.name for o in meshes if o.name in lit]
    outside = [o.name for o in meshes if o.name not in lit]
    return names, [b for n in names for b in boxes[n]], within, outside


def _bake(renderer, boxes, within, where, budget, face_size, previous, progress):
    """The worker's part: the World probe's SH at its place (the EEVEE output's World light), the region's plan and
    the volume with its bricks, packed; or ``previous`` (the probe's last volume, from the same splats) grown over
    the boxes where that is cheaper (volume_refine.extend_volume). Returns (the plan's report lines, volume,
    (irradiance, visibility, cells) images, World coefficients)."""
    from ...core.probe.volume_refine import bake_light_volume, extend_volume
    try:
        vol, messages = None, []
        if previous is not None:
            progress("growing the light volume over the meshes that left it", 0.0)
            vol = extend_volume(renderer, previous, boxes, budget, within=within, face_size=face_size,
                                progress=lambda done, total: progress(
                                    f"baking {done} of {total} new light volume probes", 0.95 * done / max(total, 1)))
            if vol is previous:
                messages = ["the light volume holds every lit mesh already: nothing baked again"]
        if vol is None:
            progress("measuring how fast the light changes", 0.0)
            plan, vol = bake_light_volume(renderer, boxes, budget, within, face_size, lambda done, total: progress(
                f"baking {done} of about {total} light volume probes", 0.1 + 0.85 * min(done / max(total, 1), 1)))
            messages = plan.messages
        world = point_coefficients(renderer, np.asarray(where, np.float64)[None])[0]
        return messages, vol, (*pv.pack_atlas(vol), pv.pack_cells(vol)), world
    finally:
        renderer.trim(BAKE_KEEP_SHARE)


# Each probe's last light volume while the file is open, with what it was baked from (volume_state): Update When
# Moved grows it when a lit mesh leaves it (volume_light_steps(grow=True)) instead of baking it whole again. A
# reopened file's volume comes back from its packed images (kept_volume), the probe and splats it was baked from
# named beside them (KEPT_FROM), so that dragging a mesh out after reopening grows it too.
_kept: dict[tuple[str, str], tuple] = {}
KEPT_FROM = "gs_ibl_kept_from"  # on the volume's irradiance image: {"scene", "probe", "state": file_state}


def volume_state(probe: bpy.types.Object, splats: list[bpy.types.Object]) -> tuple:
    """What a kept volume stands for besides the meshes: the splats that lit it (each one's data key), the probe's
    place (its World light) and the volume's settings."""
    return (tuple((splat_cache.data_key(o), colour_space_of(o)) for o in splats), tuple(round(float(c), 9) for c in
                                                                   probe.matrix_world.translation),
            int(probe.gs_ibl_probe.volume_probes), BUDGET, FACE)


def file_state(probe: bpy.types.Object, splats: list[bpy.types.Object]) -> dict:
    """volume_state as a saved file can hold it (names, counts, matrices: the session's data keys do not survive
    reopening), JSON's own types."""
    def rounded(values) -> list[float]:
        return [round(float(v), 6) for v in values]
    return {"probe": rounded(probe.matrix_world.translation),
            "splats": [[o.name, splat_count(o), colour_space_of(o), rounded(v for row in o.matrix_world for v in row)]
                       for o in splats],
            "settings": [int(probe.gs_ibl_probe.volume_probes), BUDGET, FACE]}


def _from_file(scene: bpy.types.Scene, probe: bpy.types.Object) -> tuple | None:
    """(volume, volume_state) of the file's packed volume when it is ``probe``'s, baked from the splats that light
    it now, where the probe stands now; else None."""
    img = vn.volume_image()
    raw = img.get(KEPT_FROM) if img is not None else None
    if not raw:
        return None
    try:
        splats = lighting_set(scene, require_splats(scene, probe))
        d = json.loads(raw)
        if (d.get("scene"), d.get("probe")) != (scene.name, probe.name) or d.get("state") != json.loads(
                json.dumps(file_state(probe, splats))):
            return None
        vis, cells, spec, tiles = vn.visibility_image(), vn.cells_image(), vn.volume_spec(img), vn.volume_tiles(img)
        if vis is None or cells is None or spec is None or tiles is None:
            return None
        vol = pv.unpack_volume(*(image_pixels(i)[..., :3] for i in (img, vis, cells)), spec, int(tiles))
    except (ValueError, KeyError, TypeError, ReferenceError):  # an image or a property edited or gone: bake anew
        return None
    return vol, volume_state(probe, splats)


def forget_volumes() -> None:
    """Drop every kept volume (another file is being opened: its probes' names mean other probes)."""
    _kept.clear()


def kept_volume(scene: bpy.types.Scene, probe: bpy.types.Object):
    """The probe's last light volume (core LightVolume), or None: baked in this session, or read back from the
    file's images (a reopened file) when they are this probe's, from the splats that light it now."""
    kept = _kept.get((scene.name, probe.name))
    if kept is None:
        kept = _from_file(scene, probe)
        if kept is not None:
            _kept[(scene.name, probe.name)] = kept
    return None if kept is None else kept[0]


def volume_light_steps(scene: bpy.types.Scene, probe: bpy.types.Object, grow: bool = False) -> Job:
    """Lighting Volume as a job (blender/jobs.py): boxes read now, the volume baked by a worker, written at the end.
    ``grow``: where the probe's last volume was baked from the same splats, only grow it over the meshes that left
    it. Its result: (report line, {"lit": names, "outside": names, "probes": count})."""
    from ...core.probe.volume_bake import DEFAULT_FACE
    from ...core.probe.volume_region import DEFAULT_BUDGET
    splats = lighting_set(scene, require_splats(scene, probe))
    names, boxes, within, outside = volume_boxes(scene, splats)
    if not names:
        return f"{REPORT_PREFIX}no lit mesh inside the splats: every mesh keeps the World probe", {
            "lit": [], "outside": outside, "probes": 0}
    scene_name, probe_name = scene.name, probe.name
    budget = BUDGET or int(probe.gs_ibl_probe.volume_probes) or DEFAULT_BUDGET
    if grow:
        kept_volume(scene, probe)  # a reopened file's, read back
    r = yield from probe_renderer_steps(scene, probe, need_world=True)
    where = np.array(probe.matrix_world.translation, np.float64)
    state, saved = volume_state(probe, splats), file_state(probe, splats)
    kept = _kept.get((scene_name, probe_name))
    previous = kept[0] if grow and kept is not None and kept[1] == state else None
    messages, vol, (irr, vis, cells), world = yield Work(_bake, r, boxes, within, where, budget,
                                                         FACE or DEFAULT_FACE, previous, span=(0.1, 0.97))
    scene = bpy.data.scenes.get(scene_name)  # after the worker: by name (see blender/bake.py _named)
    probe = scene.objects.get(probe_name) if scene is not None else None
    if probe is None:
        raise ValueError(f"{probe_name!r} was deleted while its light volume was baked: nothing was written")
    s = probe.gs_ibl_probe
    lit = [scene.objects[n] for n in names if n in scene.objects]  # deleted meanwhile: skipped
    for obj in lit:
        ll.set_object_grid(obj, ll.VOLUME_KEY)
    ll.prune_atlas()  # before the group is rebuilt: tiles nobody reads any more (volume_nodes.py says why)
    grids = sorted(o.name for o in bpy.data.objects if ll.has_local_light(o) in ("probe", "grid"))
    store_volume(irr, vis, cells, vol.spec, vol.tiles, world, s.irradiance_image)
    vn.volume_image()[KEPT_FROM] = json.dumps({"scene": scene_name, "probe": probe_name, "state": saved})
    for obj in lit:
        ll.light_object(obj, float(s.strength))
        obj[AUTO_KEY] = probe.name
    for n in outside:  # light this probe gave before, now outside the splats: the World's again
        obj = scene.objects.get(n)
        if obj is not None and obj.get(AUTO_KEY) == probe.name:
            ll.unlight_object(obj)
            del obj[AUTO_KEY]
    bricks = int((vol.cells > 1).sum())
    lines = [f"{REPORT_PREFIX}{len(lit)} mesh{'es share' if len(lit) != 1 else ' has'} a grid of "
             f"{' x '.join(map(str, vol.spec.shape))} probes, {pv.spacing_words(vol.spec)}"
             + (f", and {bricks} brick{'s' if bricks != 1 else ''} of finer probes" if bricks else "")
             + f", from {len(splats)} splat object{'s' if len(splats) != 1 else ''}"]
    _kept[(scene_name, probe_name)] = (vol, state)
    # a volume that needed nothing: its report was the bake's that made it (said by messages, not repeated)
    lines += messages + ([] if previous is not None and vol is previous else vol.report)
    if outside:
        lines.append(f"{len(outside)} meshes outside the splats keep the World probe: " + ", ".join(outside[:6])
                     + (", ..." if len(outside) > 6 else ""))
    if s.auto_update:
        lines.append("a mesh moved out of the volume's box grows it once the mesh stays still (Update When Moved: only "
                     "the new part is rendered)")
    else:
        lines.append("a mesh moved out of the volume's box fades to the World probe's light; re-bake to cover it (with "
                     "Update When Moved the volume grows over it, rendering only the new part)")
    if grids:  # local_light.prune_atlas: one shader cannot hold both lookups in Cycles
        lines.append("Warning: " + ", ".join(grids[:4]) + (", ..." if len(grids) > 4 else "") + " still have "
                     "per-object probes or grids (another probe's, or More Than One Probe's): Cycles cannot hold "
                     "those and the volume in one shader (the meshes render black there); use Lighting Volume on "
                     "that probe too, or Remove Local Light from them")
    s.local_report = "\n".join(lines)
    return lines[0], {"lit": [o.name for o in lit], "outside": outside, "probes": vol.timings.get("probes"),
                      "grid": vol.spec.count, "bricks": vol.brick_count}


def store_volume(irr_atlas: np.ndarray, vis_atlas: np.ndarray, cells: np.ndarray, spec, tiles: int, world=None,
                 irradiance: bpy.types.Image | None = None) -> dict:
    """Write the volume's three images (pack_atlas's two atlases of ``tiles`` maps, pack_cells') into the file's
    packed images (in place where they exist: the groups' texture nodes keep pointing at them), the spec and the
    World's numbers beside them, and rebuild the volume groups and the local-light group; returns the volume groups
    {engine: group}. ``world``: (9, 3) monomial coefficients of the World probe's light; ``irradiance``: its
    irradiance image (local_light's WORLD_COEFFS / WORLD_IRRADIANCE)."""
    irr = packed_float_image(irr_atlas, vn.volume_image(), vn.IRRADIANCE_ROLE, vn.IRRADIANCE_IMAGE)
    vis = packed_float_image(vis_atlas, vn.visibility_image(), vn.VISIBILITY_ROLE, vn.VISIBILITY_IMAGE)
    cel = packed_float_image(cells, vn.cells_image(), vn.CELLS_ROLE, vn.CELLS_IMAGE)
    irr[vn.SPEC] = json.dumps({"lo": list(map(float, spec.lo)), "hi": list(map(float, spec.hi)),
                               "shape": [int(x) for x in spec.shape], "tiles": int(tiles)})
    if world is not None:
        irr[ll.WORLD_COEFFS] = json.dumps(np.asarray(world, np.float64).reshape(-1, 3).tolist())
    if isinstance(irradiance, bpy.types.Image):
        irr[ll.WORLD_IRRADIANCE] = irradiance
    trees = vn.build_groups(irr, vis, cel, spec, tiles)
    ll.rebuild_group()
    return trees

