"""Which image the overlay draws for each splat object and region, and when it is rendered.

Per splat object one SplatOverlay over the object's shared GPU renderer (splat_cache), per region its last image
and textures. The draw handler never waits for the GPU: a slow frame, the first upload of an object and any frame
while a job's worker holds the GPU are left to a worker (blender/common/jobs.py), and the region's last image is
drawn until the new one is ready.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..common.jobs import Work, busy, gpu, modal_running, running
from ..common.jobs import start as start_job
from ..common.redraw import tag_redraw
from ..splats import cache as splat_cache
from ..splats.object import is_splat_object
from .overlay_gpu import textures
from .overlay_math import SplatOverlay, ViewMotion

_overlays: dict[int, SplatOverlay] = {}  # splat_cache.uid(object) -> its images over the shared renderer
_textures: dict[tuple[int, int], tuple] = {}  # (object uid, region) -> (image, colour texture, depth texture)
motion = ViewMotion()  # which views are moving (drawn coarse) and when to refine them
upload_error: str | None = None  # why the last upload of splats for the overlay failed


def reset_motion() -> None:
    """Views that changed while the overlay was hidden are drawn at full resolution at once."""
    global motion
    motion = ViewMotion()


def overlay_for(obj: bpy.types.Object) -> SplatOverlay:
    """The object's overlay: its images over the renderer splat_cache shares with bakes (new when that changes)."""
    splats = splat_cache.get(obj)
    ov = _overlays.get(splat_cache.uid(obj))
    if ov is not None and ov.renderer is splats.renderer:
        return ov
    if ov is not None:
        ov.close()  # its images only: the renderer belongs to splat_cache
    # the host copy (base colour only) is what a big scene's motion copy is merged from (overlay_math.MotionCopy)
    # The motion copy is built after the first full frame (SplatOverlay.image, when that frame was slow), not now:
    # built beside it, on a CPU device, it delayed the first sight of a 3M-splat scene by ~7 s (capture_bench).
    ov = SplatOverlay(renderer=splats.renderer, motion_scene=splats.host)
    _overlays[splat_cache.uid(obj)] = ov
    return ov


def clear_cache() -> None:
    """Drop the overlay's images and textures (the uploaded splats stay in splat_cache for bakes)."""
    for ov in _overlays.values():
        ov.close()
    _overlays.clear()
    _textures.clear()


def splat_image(obj: bpy.types.Object, region_3d, width: int, height: int, scale: float, slot: object = 0):
    """The OverlayImage the handler would draw for ``obj`` in a view, rendered now (works in background mode)."""
    return overlay_for(obj).image(np.array(region_3d.view_matrix), np.array(region_3d.window_matrix),
                                  width, height, scale, slot, moving=motion.moving(slot))


STILL_ON_MAIN_MS = 60.0  # a frame whose object last rendered slower than this is rendered by a worker instead


def image_now(obj: bpy.types.Object, region_3d, width: int, height: int, scale: float, slot: object,
               wait: bool = False):
    """The image to draw for ``obj`` now. Rendered here when its splats are on the GPU, no job holds it and the
    render is quick (the object's last full render took under STILL_ON_MAIN_MS, or the frame is the motion copy's);
    otherwise the last image drawn in this region (None before the first) is drawn while a background job uploads
    the splats (Show Splats on a 3M-splat object: seconds of reading and upload), a bake's worker uses the GPU, or
    a worker renders the frame (a still frame of 3M splats takes seconds on a CPU device): the main thread never
    waits for one. ``wait``: render here whatever it costs (picking needs this view's image)."""
    last = _textures.get((splat_cache.uid(obj), slot))
    last = last[0] if last else None
    if splat_cache.current(obj) is None:
        _start_upload(obj)  # without a window (blender -b) it has run now
        if splat_cache.current(obj) is None:
            return last
    if not gpu.acquire(blocking=False):
        _schedule_retry()
        return last
    try:
        ov = overlay_for(obj)
        view, window = np.array(region_3d.view_matrix), np.array(region_3d.window_matrix)
        moving = motion.moving(slot)
        quick = (ov.full_ms is not None and ov.full_ms <= STILL_ON_MAIN_MS) or (moving and ov.coarse_when_moving())
        if wait or quick or ov.cached(view, window, width, height, scale, slot, moving) is not None:
            return ov.image(view, window, width, height, scale, slot, moving=moving)
    finally:
        gpu.release()
    key = f"render:{splat_cache.uid(obj)}:{slot}"
    if busy(key) is None and not modal_running():  # a bake the user waits for goes first; its end redraws
        start_job(key, _render_job(ov, view, window, width, height, scale, slot, moving), f"drawing {obj.name}",
                  done=lambda _runner: tag_redraw())
    return last


def _render_job(ov: SplatOverlay, view, window, width: int, height: int, scale: float, slot: object, moving: bool):
    """One overlay frame rendered by a worker; the next draw of the same view finds it in ``ov``'s images."""
    yield Work(lambda progress: ov.image(view, window, width, height, scale, slot, moving=moving))


def _start_upload(obj: bpy.types.Object) -> None:
    key = splat_cache.upload_key(obj)
    if busy(key) is None:
        start_job(key, splat_cache.get_steps(obj, wait_for_upload=False), f"showing {obj.name}", done=_uploaded)


def _uploaded(runner) -> None:
    global upload_error
    if runner.error is not None:
        upload_error = str(runner.error)
        print(f"GS-IBL overlay: {upload_error}")
    tag_redraw()


_retry_scheduled = False


def _schedule_retry() -> None:
    """Draw again once the GPU is free (a job's worker held it at the last draw)."""
    global _retry_scheduled
    if _retry_scheduled:
        return
    _retry_scheduled = True

    def retry() -> float | None:
        global _retry_scheduled
        if any(r.working for r in running()):
            return 0.25
        _retry_scheduled = False
        tag_redraw()
        return None

    bpy.app.timers.register(retry, first_interval=0.25)


def textures_for(key: tuple[int, int], img) -> tuple:
    cached = _textures.get(key)
    if cached is not None and cached[0] is img:  # identity: ids of freed images recur
        return cached[1], cached[2]
    colour, depth = textures(img.rgba, img.depth)
    _textures[key] = (img, colour, depth)
    return colour, depth


def forget_undrawn(slot: int, drawn: set[int]) -> None:
    """Free the textures of objects this region no longer draws, and the images of deleted splat objects (their
    renderers are freed by splat_cache); otherwise they would stay on the GPU until Show Splats is turned off."""
    for key in [k for k in _textures if k[1] == slot and k[0] not in drawn]:
        del _textures[key]
    if len(_overlays) > len(drawn):
        live = {splat_cache.uid(o) for o in bpy.data.objects if is_splat_object(o)}
        for uid in [u for u in _overlays if u not in live]:
            _overlays.pop(uid).close()
