"""The scene's side of splats in renders, on the main thread: the compositor nodes and images in place while the
setting *Splats in Renders* (Scene.gs_ibl_render.enabled) is on and the scene has splats to render, taken out when
it is turned off; the splat objects' point proxy kept out of renders; what the panel says F12 will contain.

The render handlers themselves (frame.py) may run on the render job's thread (F12 in the window), where datablocks
must not be made (docs/final-frame.md, section 7), so everything here happens before: when the setting changes, when
a splat object changes (a depsgraph update: its camera icon turned on, a new import), when a file is loaded, and
at the start of a render that runs on the main thread (``blender -b``, scripts).
"""
from __future__ import annotations

import bpy

from ..splats import cache as splat_cache
from ..splats.object import is_mesh_splats, is_native_splats
from . import compositor
from .splats import draws_native, proxy_modifiers, render_visible


def settings(scene):
    return getattr(scene, "gs_ibl_render", None)


def enabled(scene) -> bool:
    s = settings(scene)
    return bool(s is not None and s.enabled)


def keep_proxy_out_of_renders(ob) -> None:
    """Our splat object's point proxy is a viewport stand-in: with the camera icon on, Cycles and EEVEE would render
    its points besides our splats."""
    for mod in proxy_modifiers(ob):
        if mod.show_render:
            splat_cache.proxy_switched(ob)  # a display switch, not an edit of the splats: no re-upload
            mod.show_render = False


def ensure(scene) -> None:
    """Our nodes and images in place if the setting is on and the scene has splats to render (idempotent: writes
    nothing when all is in place, so the depsgraph update it may cause ends here)."""
    if not enabled(scene):
        return
    drawn, hidden, _native = render_visible(scene)
    for ob in drawn + hidden:
        keep_proxy_out_of_renders(ob)
    if drawn or compositor.installed(scene):
        compositor.install(scene, write_pass=bool(settings(scene).write_pass))


def disable(scene) -> None:
    compositor.remove(scene)


def enabled_changed(scene) -> None:
    """The setting was switched (its update callback)."""
    if enabled(scene):
        ensure(scene)
    else:
        disable(scene)


def describe(scene, view_layer=None) -> tuple[str, list[str]]:
    """What F12 will contain, in a line for the panel, and notes (objects left out, and why)."""
    drawn, hidden, native = render_visible(scene, view_layer)
    notes = []
    if native:
        notes.append(f"Blender renders its own splats: {', '.join(o.name for o in native)}")
    if not enabled(scene):
        return "F12: meshes only (Splats in Renders is off)", notes
    if hidden:
        names = ", ".join(o.name for o in hidden)
        notes.append(f"Left out of F12: {names} (camera icon off, or not in this view layer)")
    if not drawn:
        return "F12: no GS-IBL splats (no splat object has its camera icon on)", notes
    if scene.camera is None:
        return "F12: no splats: the scene has no camera", notes
    if scene.camera.data.type != "PERSP":
        return "F12: no splats: the camera is not perspective", notes
    names = ", ".join(o.name for o in drawn)
    rs = scene.gs_ibl_render
    extras = (["the meshes' shadows on them"] if getattr(rs, "shadows", False) else []) + [
        "a transparent background" if compositor.transparent(scene) else "the World behind"]
    return f"F12: meshes and the splats of {names}, by depth; " + ", ".join(extras), notes


def on_depsgraph_update(scene, depsgraph) -> None:
    """A splat object changed (a new import, its camera icon, ...): our nodes in place if it is now rendered (a
    native one where Native Splats is GS-IBL; frame.py calls this outside renders only)."""
    if not enabled(scene):
        return
    for u in depsgraph.updates:
        idb = getattr(u.id, "original", u.id)
        if isinstance(idb, bpy.types.Object) and (is_mesh_splats(idb)
                                                  or (is_native_splats(idb) and draws_native(scene))):
            ensure(scene)
            return


def on_load_post() -> None:
    for scene in bpy.data.scenes:
        ensure(scene)
