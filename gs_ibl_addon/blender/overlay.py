"""Viewport overlay: the splats, rendered by our renderer from each 3D View's camera, depth-tested against meshes.

A SpaceView3D POST_VIEW draw handler. Blender calls it after every engine and its own overlays (grid, wires,
extras) have drawn, with the scene's depth buffer bound. Per splat object it keeps one SplatOverlay over the
object's shared GPU renderer (splat_cache: uploaded once, shared with probe bakes, re-uploaded only when the
object moves or its mesh changes) and per viewport region the last image, re-rendered only when the view, the
region size or the resolution changed (overlay_math). While a view moves it is rendered at a quarter of the
resolution and refined by one timed redraw once the view has been still for SETTLE_S (overlay_math.ViewMotion);
a scene too big to follow the mouse draws its motion copy meanwhile (overlay_math.MotionCopy). The handler never
waits for the GPU: a frame whose object last rendered slower than STILL_ON_MAIN_MS (a CPU device: a still frame of
3M splats takes seconds), the first upload of an object and any frame while a job's worker holds the GPU are left
to a worker (blender/jobs.py), and the region's last image is drawn until the new one is ready.

The splats are drawn into Blender's overlay layer by one pass of a shader of ours (overlay_math.composite is its
numpy reference): it reads back what Blender drew there and the scene depth (8-bit colour and float depth), turns
the renderer's depth into window depth and composites up to MAX_LAYERS splat objects per pixel, nearest first.
On llvmpipe (1311x878 region, 2 cores) read-back, packing and upload take 15-40 ms and the pass about 130 ms: a
redraw of a still view costs the overlay ~170 ms after Blender's own drawing, against ~100 ms for the plain quads
(tests/real_blender/test_gui_overlay.py prints both); the read-back also waits for Blender's drawing to finish. So a mesh in front of the splats hides them and splats in front of a mesh hide it; a mesh
edge keeps its anti-aliasing (the splats replace the background in the part of the edge pixel the mesh does not
cover, as Blender's background pass left it); the floor grid, which writes its depth, never shows through splats;
and the 3D cursor and object origins stay on top of them. Exposure and the clip are applied per pixel on the GPU
(the overlay layer is sRGB: the GPU encodes what the shader writes). The textures hold the renderer's linear
premultiplied colour and distance as they come: changing Exposure uploads nothing. More objects than MAX_LAYERS
are drawn as depth-tested quads (draw_quads), without those refinements.
While the overlay shows, splat objects draw nothing of their own (hide_helpers): Blender's lines and points
(loose vertices as black dots, bounds boxes) would show over the splats. picking.py puts the 3D cursor on the
splats and selects splat objects by clicking them, from the images drawn here (splats_under_mouse).
"""
from __future__ import annotations

import math
import time
from collections import deque

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import splat_cache
from .jobs import Work, busy, gpu, modal_running, running
from .jobs import start as start_job
from ..core.colour import linear_to_srgb, srgb_to_linear
from .overlay_math import (BACKGROUND_KINDS, COVERAGE_EPS, DEPTH_PULL, EDGE_REACH, GRID_TOLERANCE, LINE_CUT,
                           LINE_REACH, MAX_LAYERS, SplatOverlay, ViewMotion, splat_hit, view_key)
from .compat import get_modifier_input, modifier_input_identifiers, set_modifier_input
from .splat_object import PROXY_MODIFIER, is_mesh_splats, is_splat_object

HIDDEN_KEY = "gs_ibl_proxy_fraction"  # on a splat object while the overlay shows: its proxy's fraction to restore
ALPHA_CUT = 1.0 / 255.0  # fragments with less coverage are not drawn
OPAQUE_CUT = 0.5  # the depth pass writes the depth of pixels at least this covered; picking's opaque enough
MAX_DISCS = 64  # cursor and origin discs kept on top of the splats

_handle = None
_overlays: dict[int, SplatOverlay] = {}  # splat_cache.uid(object) -> its images over the shared renderer
_textures: dict[tuple[int, int], tuple] = {}  # (object uid, region) -> (image, colour texture, depth texture)
_motion = ViewMotion()
_refine_scheduled = False
_shader = None
_composite_shader = None
_dummy = None
last_error: str | None = None
last_draw: dict = {}  # what the last draw did, per region (scale, render ms): read by tests and the GUI check
draw_log: deque = deque(maxlen=64)  # (time, region, scale, render ms, draw ms) of recent draws, for the GUI check
capture: dict = {}  # set capture["next"] = True: the next composite keeps its inputs and output (the GUI check)
use_composite = True  # False: the plain depth-tested quads only (the GUI check compares the two)
timing: dict = {}  # the last composite's parts, ms: read back (colour, depth), pack, upload, draw calls

_VERTEX = """
void main() {
  uv = texCoord;
  gl_Position = vec4(pos, 0.0, 1.0);
}
"""
# overlay_math.layer_colour and overlay_math.window_depth, per pixel: colour premultiplied by coverage, clipped at
# it, linear (the overlay layer is sRGB: the GPU encodes on write); distance along the view axis -> window depth
# through the viewport's projection (1: no splat).
_FRAGMENT = """
void main() {
  vec4 c = texture(image, uv);
  if (c.a < alpha_cut) {
    discard;
  }
  float a = clamp(c.a, 0.0, 1.0);
  fragColor = vec4(clamp(c.rgb * exposure_scale, vec3(0.0), vec3(max(c.a, 0.0))), a);
  float d = texture(depth_image, uv).r;
  float z = -(d - depth_offset) * (1.0 - depth_pull);
  float w = depth_proj.z * z + depth_proj.w;
  float win = 0.5 * (depth_proj.x * z + depth_proj.y) / w + 0.5;
  gl_FragDepth = (d > 0.0 && w > 0.0 && win >= 0.0 && win <= 1.0) ? win : 1.0;
}
"""


# overlay_math.composite per pixel (see its docstring), in one pass written over the overlay layer (no blending):
# snapshot_rg and snapshot_ba hold its bytes as Blender left them (r + 256 g, b + 256 a: exact in a float; Blender's
# GPUTexture takes float data only), scene_depth_tx the scene depth, all read back just before. One splat layer (the
# usual case) takes a path of its own: llvmpipe runs per-pixel arrays and their dynamic indexing slowly.
_COMPOSITE_FRAGMENT = """
#define LINE_CUT %(line_cut).9g
#define COVERAGE_EPS %(coverage_eps).9g
#define EDGE_REACH %(edge_reach)d
#define LINE_REACH %(line_reach)d

float srgb_lin(float c) {
  return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

ivec2 clamp_px(ivec2 p) {
  return clamp(p, ivec2(0), ivec2(region.xy) - 1);
}

vec2 snapshot(ivec2 p) {
  float v = texelFetch(snapshot_ba, p, 0).r;
  float a = floor(v / 256.0 + 1e-3);
  return vec2(v - 256.0 * a, a) / 255.0;  /* (blue as stored: sRGB-encoded, alpha) */
}

float coverage(float blue_stored, vec3 bg) {
  if (use_coverage < 0.5 || blue_stored <= 0.0) {
    return 1.0;
  }
  if (abs(blue_stored - bg_low.w) < 0.25 / 255.0) {
    return 0.0;  /* the background's own byte (one colour): no pow per pixel */
  }
  float c = clamp(1.0 - srgb_lin(blue_stored) / max(bg.b, 1e-6), 0.0, 1.0);
  return c < COVERAGE_EPS ? 0.0 : (c > 1.0 - COVERAGE_EPS ? 1.0 : c);
}

vec3 background(ivec2 p);

bool grid_at(ivec2 p, float d) {
  if (grid_normal.w <= 0.0 || d >= 1.0) {
    return false;
  }
  vec2 o = snapshot(p);
  /* the grid writes its plane's depth at its lines and where they fade out, never under a mesh */
  if (o.y < LINE_CUT && coverage(o.x, background(p)) > 0.0) {
    return false;
  }
  vec2 ndc = (vec2(p) + 0.5) / region.xy * 2.0 - 1.0;
  float nz = 2.0 * d - 1.0;
  float z = (depth_proj.y - nz * depth_proj.w) / (nz * depth_proj.z - depth_proj.x);
  float wc = depth_proj.z * z + depth_proj.w;
  float x = (ndc.x * wc - proj_x.y * z - proj_x.z) / proj_x.x;
  float y = (ndc.y * wc - proj_y.y * z - proj_y.z) / proj_y.x;
  vec3 pt = (view_inv * vec4(x, y, z, 1.0)).xyz;
  return abs(dot(pt, grid_normal.xyz)) <= grid_normal.w * length(pt - eye.xyz) + 1e-5;
}

float scene_depth(ivec2 p) {
  p = clamp_px(p);
  float d = texelFetch(scene_depth_tx, p, 0).r;
  return grid_at(p, d) ? 1.0 : d;
}

float neighbour_depth(ivec2 p, int reach) {
  float m = 1.0;
  for (int dy = -reach; dy <= reach; dy++) {
    for (int dx = -reach; dx <= reach; dx++) {
      m = min(m, scene_depth(p + ivec2(dx, dy)));
    }
  }
  return m;
}

float line_depth(ivec2 p) {
  /* lines that write no depth (outlines) lie at the nearest depth around them; a grid line's faint edge at none */
  float m = 1.0;
  for (int dy = -LINE_REACH; dy <= LINE_REACH; dy++) {
    for (int dx = -LINE_REACH; dx <= LINE_REACH; dx++) {
      ivec2 q = clamp_px(p + ivec2(dx, dy));
      float d = texelFetch(scene_depth_tx, q, 0).r;
      if (grid_at(q, d)) {
        return 1.0;
      }
      m = min(m, d);
    }
  }
  return m;
}

float window_depth(float d) {
  float z = -(d - depth_offset) * (1.0 - depth_pull);
  float w = depth_proj.z * z + depth_proj.w;
  float win = 0.5 * (depth_proj.x * z + depth_proj.y) / w + 0.5;
  return (d > 0.0 && w > 0.0 && win >= 0.0 && win <= 1.0) ? win : 1.0;
}

vec3 background(ivec2 p) {
  if (bg_high.w < 0.5) {
    return bg_high.rgb;
  }
  vec2 st = (vec2(p) + 0.5) / region.xy;
  vec3 ph = pow(bg_high.rgb, vec3(1.0 / 2.2));
  vec3 pl = pow(bg_low.rgb, vec3(1.0 / 2.2));
  if (bg_high.w < 1.5) {
    return pow(mix(pl, ph, st.y), vec3(2.2));
  }
  return pow(mix(ph, pl, length(st - 0.5) * 1.41421356), vec3(2.2));
}

bool in_disc(ivec2 p) {
  vec2 c = vec2(p) + 0.5;
  for (int i = 0; i < disc_count; i++) {
    vec4 dsc = texelFetch(disc_tx, ivec2(i, 0), 0);
    vec2 q = c - dsc.xy;
    if (dot(q, q) <= dsc.z * dsc.z) {
      return true;
    }
  }
  return false;
}

vec4 overlay_colour(ivec2 p) {
  float rg = texelFetch(snapshot_rg, p, 0).r;
  float g = floor(rg / 256.0 + 1e-3);
  vec2 o = snapshot(p);
  vec3 stored = vec3(rg - 256.0 * g, g, o.x * 255.0) / 255.0;
  return vec4(srgb_lin(stored.r), srgb_lin(stored.g), srgb_lin(stored.b), o.y);
}

#define texel(t) clamp(ivec2(uv * vec2(textureSize(t, 0))), ivec2(0), textureSize(t, 0) - 1)

/* one splat layer: premultiplied colour, coverage (0: none) and window depth at this fragment */
void layer(int k, out vec3 col, out float al, out float wd) {
  vec4 c;
  float d;
  /* colour filtered (the image may be coarser than the region), depth from the nearest texel: cheaper, and no
     depth between a near and a far surface at an edge */
  if (k == 0) { c = texture(image0, uv); d = texelFetch(depth0, texel(depth0), 0).r; }
  else if (k == 1) { c = texture(image1, uv); d = texelFetch(depth1, texel(depth1), 0).r; }
  else if (k == 2) { c = texture(image2, uv); d = texelFetch(depth2, texel(depth2), 0).r; }
  else { c = texture(image3, uv); d = texelFetch(depth3, texel(depth3), 0).r; }
  al = clamp(c.a, 0.0, 1.0);
  col = clamp(c.rgb * exposure_scale, vec3(0.0), vec3(max(c.a, 0.0)));
  wd = window_depth(d);
  if (al < alpha_cut) {
    al = 0.0;
    col = vec3(0.0);
  }
}

void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 c0, c1 = vec3(0.0), c2 = vec3(0.0), c3 = vec3(0.0);
  float a0, w0, a1 = 0.0, w1 = 1.0, a2 = 0.0, w2 = 1.0, a3 = 0.0, w3 = 1.0;
  layer(0, c0, a0, w0);
  if (layer_count > 1) {
    layer(1, c1, a1, w1);
  }
  if (layer_count > 2) {
    layer(2, c2, a2, w2);
  }
  if (layer_count > 3) {
    layer(3, c3, a3, w3);
  }
  if (a0 + a1 + a2 + a3 <= 0.0) {
    discard;
  }
  vec2 o = snapshot(p);
  float o_a = o.y;
  bool line = o_a >= LINE_CUT;
  float d_raw = texelFetch(scene_depth_tx, p, 0).r;
  bool is_grid = line && grid_at(p, d_raw);
  bool on_top = line && !is_grid && disc_count > 0 && in_disc(p);
  float d_p = is_grid ? 1.0 : d_raw;
  vec3 bg = background(p);
  float cov = 1.0;
  float split;
  if (line) {
    split = is_grid ? 1.0 : ((on_top || d_p < 1.0) ? d_p : line_depth(p));
  }
  else {
    cov = coverage(o.x, bg);
    split = cov <= 0.0 ? 1.0 : ((d_p < 1.0 || cov >= 1.0) ? d_p : neighbour_depth(p, EDGE_REACH));
  }
  vec3 pf = vec3(0.0);
  float tf = 1.0;
  vec3 pb = vec3(0.0);
  float tb = 1.0;
  if (layer_count == 1) {
    if (w0 < split) {
      pf = c0;
      tf = 1.0 - a0;
    }
    else {
      pb = c0;
      tb = 1.0 - a0;
    }
  }
  else {
    /* nearest first: repeatedly the nearest layer not taken yet (ties: the lower index, as a stable sort) */
    bool t0 = a0 <= 0.0, t1 = a1 <= 0.0, t2 = a2 <= 0.0, t3 = a3 <= 0.0;
    for (int i = 0; i < 4; i++) {
      int best = -1;
      float bd = 3.0;
      if (!t0 && w0 < bd) { bd = w0; best = 0; }
      if (!t1 && w1 < bd) { bd = w1; best = 1; }
      if (!t2 && w2 < bd) { bd = w2; best = 2; }
      if (!t3 && w3 < bd) { bd = w3; best = 3; }
      if (best < 0) {
        break;
      }
      vec3 ck = best == 0 ? c0 : (best == 1 ? c1 : (best == 2 ? c2 : c3));
      float ak = best == 0 ? a0 : (best == 1 ? a1 : (best == 2 ? a2 : a3));
      t0 = t0 || best == 0;
      t1 = t1 || best == 1;
      t2 = t2 || best == 2;
      t3 = t3 || best == 3;
      if (bd < split) {
        pf += tf * ck;
        tf *= 1.0 - ak;
      }
      else {
        pb += tb * ck;
        tb *= 1.0 - ak;
      }
    }
  }
  float af = 1.0 - tf;
  if (!line) {
    fragColor = vec4(pf + tf * (1.0 - cov) * (pb + tb * bg), af);
  }
  else {
    vec4 ov = overlay_colour(p);
    if (on_top) {
      vec3 xbg = d_p < 1.0 ? vec3(0.0) : bg;
      fragColor = vec4(ov.rgb + (1.0 - ov.a) * (pf - af * xbg), ov.a + (1.0 - ov.a) * af);
    }
    else {
      fragColor = vec4(pf + tf * ov.rgb, af + tf * ov.a);
    }
  }
}
""" % {"line_cut": LINE_CUT, "coverage_eps": COVERAGE_EPS, "edge_reach": EDGE_REACH, "line_reach": LINE_REACH}


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
                                  width, height, scale, slot, moving=_motion.moving(slot))


STILL_ON_MAIN_MS = 60.0  # a frame whose object last rendered slower than this is rendered by a worker instead


def _image_now(obj: bpy.types.Object, region_3d, width: int, height: int, scale: float, slot: object,
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
        moving = _motion.moving(slot)
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
    global last_error
    if runner.error is not None:
        last_error = str(runner.error)
        print(f"GS-IBL overlay: {last_error}")
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


def _quad_info(iface_name: str):
    """A shader description for a screen quad: position and texture coordinate in, uv out, _VERTEX as its vertex
    stage; the caller adds its samplers, constants and fragment stage."""
    import gpu
    iface = gpu.types.GPUStageInterfaceInfo(iface_name)
    iface.smooth("VEC2", "uv")
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, "VEC2", "pos")
    info.vertex_in(1, "VEC2", "texCoord")
    info.vertex_out(iface)
    info.vertex_source(_VERTEX)
    return info


def _shader_get():
    """Our image shader: display colour and gl_FragDepth from the renderer's images (made once per session)."""
    global _shader
    if _shader is None:
        import gpu
        info = _quad_info("gs_ibl_overlay_iface")
        info.sampler(0, "FLOAT_2D", "image")
        info.sampler(1, "FLOAT_2D", "depth_image")
        info.push_constant("FLOAT", "alpha_cut")
        info.push_constant("FLOAT", "exposure_scale")
        info.push_constant("VEC4", "depth_proj")  # window matrix P22, P23, P32, P33
        info.push_constant("FLOAT", "depth_offset")
        info.push_constant("FLOAT", "depth_pull")
        info.fragment_out(0, "VEC4", "fragColor")
        if hasattr(info, "depth_write"):  # Vulkan/Metal backends must be told; OpenGL needs no declaration
            info.depth_write("ANY")
        info.fragment_source(_FRAGMENT)
        _shader = gpu.shader.create_from_info(info)
    return _shader


def _composite_shader_get():
    """The composite shader (made once per session)."""
    global _composite_shader
    if _composite_shader is None:
        import gpu
        info = _quad_info("gs_ibl_composite_iface")
        info.sampler(0, "FLOAT_2D", "snapshot_ba")  # b + 256 a
        info.sampler(11, "FLOAT_2D", "snapshot_rg")  # r + 256 g
        info.sampler(1, "FLOAT_2D", "scene_depth_tx")
        info.sampler(2, "FLOAT_2D", "disc_tx")
        for k in range(MAX_LAYERS):
            info.sampler(3 + k, "FLOAT_2D", f"image{k}")
            info.sampler(3 + MAX_LAYERS + k, "FLOAT_2D", f"depth{k}")
        info.push_constant("INT", "layer_count")
        info.push_constant("INT", "disc_count")
        info.push_constant("FLOAT", "alpha_cut")
        info.push_constant("FLOAT", "exposure_scale")
        info.push_constant("FLOAT", "depth_offset")
        info.push_constant("FLOAT", "depth_pull")
        info.push_constant("FLOAT", "use_coverage")
        info.push_constant("VEC4", "depth_proj")  # window matrix P22, P23, P32, P33
        info.push_constant("VEC4", "proj_x")  # P00, P02, P03
        info.push_constant("VEC4", "proj_y")  # P11, P12, P13
        info.push_constant("VEC4", "region")  # width, height
        info.push_constant("VEC4", "bg_high")  # rgb, kind (0 one colour, 1 linear gradient, 2 radial)
        info.push_constant("VEC4", "bg_low")
        info.push_constant("VEC4", "grid_normal")  # xyz, tolerance (0: no grid)
        info.push_constant("VEC4", "eye")
        info.push_constant("MAT4", "view_inv")
        info.fragment_out(0, "VEC4", "fragColor")
        info.fragment_source(_COMPOSITE_FRAGMENT)
        _composite_shader = gpu.shader.create_from_info(info)
    return _composite_shader


def _dummies():
    global _dummy
    if _dummy is None:
        _dummy = (_float_texture(np.zeros((1, 1, 4), np.float32), "RGBA32F"),
                  _float_texture(np.zeros((1, 1), np.float32), "R32F"))
    return _dummy


def composite_params(window_matrix, view_matrix, width: int, height: int, background: dict, grid_normal=None,
                     discs=()) -> dict:
    """The composite shader's view uniforms: projection rows, region size, background (overlay_math
    .viewport_background's kind, high and low colours, use_coverage), grid plane, cursor and origin discs."""
    p = np.asarray(window_matrix, np.float64)
    inv = np.linalg.inv(np.asarray(view_matrix, np.float64))
    kind = float(BACKGROUND_KINDS[background["kind"]])
    gn = (0.0, 0.0, 0.0, 0.0) if grid_normal is None else (*map(float, grid_normal), GRID_TOLERANCE)
    return {"proj_x": (float(p[0, 0]), float(p[0, 2]), float(p[0, 3]), 0.0),
            "proj_y": (float(p[1, 1]), float(p[1, 2]), float(p[1, 3]), 0.0),
            "region": (float(width), float(height), 0.0, 0.0),
            "bg_high": (*map(float, background["high"]), kind),
            # w: the single-colour background's blue as the overlay layer stores it (sRGB, 8 bits), else -1
            "bg_low": (*map(float, background["low"]), float(np.round(linear_to_srgb(np.array(background["high"][2]))
                                                                     * 255.0) / 255.0) if kind == 0 else -1.0),
            "use_coverage": 1.0 if background["use_coverage"] else 0.0,
            "grid_normal": gn, "eye": (*map(float, inv[:3, 3]), 1.0),
            "view_inv": [float(x) for x in inv.T.ravel()],  # column-major, as GLSL's mat4
            "discs": [tuple(map(float, d)) for d in discs]}


def draw_composite(snapshot: tuple, depth_tex, layers: list[tuple], rect, shading: tuple, params: dict) -> None:
    """The region's splat images (colour and depth textures; composited nearest first per pixel) written over the
    bound overlay layer, given its snapshot (textures of its r + 256 g and b + 256 a bytes, and the window depth):
    overlay_math.composite, one pass, no blending (pixels no splat covers are left alone)."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    shader = _composite_shader_get()
    x0, y0, x1, y1 = rect
    batch = batch_for_shader(shader, "TRI_FAN", {"pos": ((x0, y0), (x1, y0), (x1, y1), (x0, y1)),
                                                 "texCoord": ((0, 0), (1, 0), (1, 1), (0, 1))})
    discs = params["discs"][:MAX_DISCS]
    disc_tex = (_float_texture(np.array([[(*d, 0.0) for d in discs]], np.float32), "RGBA32F") if discs
                else _dummies()[0])
    k, proj, offset, pull = shading
    saved = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get())
    gpu.state.depth_test_set("NONE")
    gpu.state.depth_mask_set(False)
    gpu.state.blend_set("NONE")
    try:
        shader.bind()
        shader.uniform_sampler("snapshot_rg", snapshot[0])
        shader.uniform_sampler("snapshot_ba", snapshot[1])
        shader.uniform_sampler("scene_depth_tx", depth_tex)
        shader.uniform_sampler("disc_tx", disc_tex)
        for i in range(MAX_LAYERS):
            colour, depth = layers[i] if i < len(layers) else _dummies()
            shader.uniform_sampler(f"image{i}", colour)
            shader.uniform_sampler(f"depth{i}", depth)
        shader.uniform_int("layer_count", len(layers))
        shader.uniform_int("disc_count", len(discs))
        shader.uniform_float("alpha_cut", ALPHA_CUT)
        shader.uniform_float("exposure_scale", k)
        shader.uniform_float("depth_offset", offset)
        shader.uniform_float("depth_pull", pull)
        shader.uniform_float("depth_proj", proj)
        for name in ("use_coverage", "proj_x", "proj_y", "region", "bg_high", "bg_low", "grid_normal", "eye"):
            shader.uniform_float(name, params[name])
        shader.uniform_float("view_inv", params["view_inv"])
        batch.draw(shader)
    finally:
        gpu.state.depth_test_set(saved[0])
        gpu.state.depth_mask_set(saved[1])
        gpu.state.blend_set(saved[2])


def _float_texture(px: np.ndarray, fmt: str):
    import gpu
    px = np.ascontiguousarray(px[::-1], np.float32)  # GPU rows go bottom-up
    h, w = px.shape[:2]
    return gpu.types.GPUTexture((w, h), format=fmt, data=gpu.types.Buffer("FLOAT", px.size, px.ravel()))


def shader_params(view, exposure: float, pull: float = DEPTH_PULL) -> tuple:
    """The shader's per-image uniforms: (exposure scale, (P22, P23, P32, P33), depth offset, pull)."""
    p = view.window_matrix
    return (float(2.0 ** exposure), (float(p[2, 2]), float(p[2, 3]), float(p[3, 2]), float(p[3, 3])),
            float(view.depth_offset), float(pull))


def textures(rgba: np.ndarray, depth: np.ndarray) -> tuple:
    """GPU textures of the renderer's premultiplied linear colour and its distance image (rows top first)."""
    return _float_texture(rgba, "RGBA32F"), _float_texture(depth, "R32F")


def _textures_for(key: tuple[int, int], img) -> tuple:
    cached = _textures.get(key)
    if cached is not None and cached[0] is img:  # identity: ids of freed images recur
        return cached[1], cached[2]
    colour, depth = textures(img.rgba, img.depth)
    _textures[key] = (img, colour, depth)
    return colour, depth


def draw_quads(quads: list[tuple]) -> None:
    """Two passes over the splat objects' images (colour texture, depth texture, NDC rectangle, shader_params),
    far first.

    The depth pass writes the depth of the well-covered pixels of every object, so in the colour pass an object
    is hidden where another one's splats are in front of it, whatever their order (a room drawn after a small
    capture inside it would otherwise cover it). The colour pass blends each image, premultiplied, where it is
    not behind a mesh or another object's splats; soft edges blend in the far-first order.
    """
    import gpu
    from gpu_extras.batch import batch_for_shader
    shader = _shader_get()
    batches = [batch_for_shader(shader, "TRI_FAN", {"pos": ((x0, y0), (x1, y0), (x1, y1), (x0, y1)),
                                                    "texCoord": ((0, 0), (1, 0), (1, 1), (0, 1))})
               for _c, _d, (x0, y0, x1, y1), _p in quads]
    saved = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get())
    gpu.state.depth_test_set("LESS_EQUAL")
    try:
        shader.bind()
        for colour_pass in (False, True):
            gpu.state.color_mask_set(colour_pass, colour_pass, colour_pass, colour_pass)
            gpu.state.depth_mask_set(not colour_pass)
            gpu.state.blend_set("ALPHA_PREMULT" if colour_pass else "NONE")
            shader.uniform_float("alpha_cut", ALPHA_CUT if colour_pass else OPAQUE_CUT)
            for (colour, depth, _rect, (k, proj, offset, pull)), batch in zip(quads, batches):
                shader.uniform_sampler("image", colour)
                shader.uniform_sampler("depth_image", depth)
                shader.uniform_float("exposure_scale", k)
                shader.uniform_float("depth_proj", proj)
                shader.uniform_float("depth_offset", offset)
                shader.uniform_float("depth_pull", pull)
                batch.draw(shader)
    finally:
        gpu.state.color_mask_set(True, True, True, True)
        gpu.state.depth_test_set(saved[0])
        gpu.state.depth_mask_set(saved[1])
        gpu.state.blend_set(saved[2])


def _forget_undrawn(slot: int, drawn: set[int]) -> None:
    """Free the textures of objects this region no longer draws, and the images of deleted splat objects (their
    renderers are freed by splat_cache); otherwise they would stay on the GPU until Show Splats is turned off."""
    for key in [k for k in _textures if k[1] == slot and k[0] not in drawn]:
        del _textures[key]
    if len(_overlays) > len(drawn):
        live = {splat_cache.uid(o) for o in bpy.data.objects if is_splat_object(o)}
        for uid in [u for u in _overlays if u not in live]:
            _overlays.pop(uid).close()


def viewport_background(context) -> dict:
    """How Blender's overlay fills this 3D View's background (overlay_background.hh): kind (overlay_math
    .BACKGROUND_KINDS), high and low linear colours, and whether the overlay layer holds it (Solid and Wireframe
    shading; Material Preview and Rendered draw their World into the render instead) so a pixel's render coverage
    can be read from it (its blue channel: not for backgrounds with almost no blue)."""
    shading = context.space_data.shading
    scene = context.scene
    if shading.type in {"WIREFRAME", "SOLID"}:
        if shading.background_type == "WORLD" and scene.world is not None:
            high = low = tuple(scene.world.color)
            kind = "SINGLE_COLOR"
        elif shading.background_type == "VIEWPORT":
            high = low = tuple(shading.background_color)
            kind = "SINGLE_COLOR"
        else:
            g = context.preferences.themes[0].view_3d.space.gradients
            high = tuple(srgb_to_linear(np.array(g.high_gradient)))
            low = tuple(srgb_to_linear(np.array(g.gradient)))
            kind = g.background_type if g.background_type in BACKGROUND_KINDS else "SINGLE_COLOR"
        blues = (high[2], low[2])
        use = min(blues) >= max(1.0 / 255.0, 0.25 * max(*high, *low))
        return {"kind": kind, "high": high, "low": low, "use_coverage": use}
    return {"kind": "SINGLE_COLOR", "high": (0.0, 0.0, 0.0), "low": (0.0, 0.0, 0.0), "use_coverage": False}


def grid_normal(space, rv3d):
    """The plane Blender draws its grid in and writes the depth of (through the origin): the floor in perspective
    and free orthographic views, the view plane in an axis-aligned orthographic view; None when it is not drawn."""
    ov = space.overlay
    if not ov.show_overlays:
        return None
    if not rv3d.is_perspective and rv3d.is_orthographic_side_view:
        if not ov.show_ortho_grid:
            return None
        return tuple(np.array(rv3d.view_matrix)[2, :3])
    return (0.0, 0.0, 1.0) if ov.show_floor else None


_PAINT_MODES = {"PAINT_WEIGHT", "PAINT_VERTEX", "PAINT_TEXTURE", "SCULPT", "SCULPT_CURVES", "PAINT_GPENCIL",
                "PAINT_GREASE_PENCIL", "WEIGHT_GPENCIL", "VERTEX_GPENCIL", "SCULPT_GPENCIL", "WEIGHT_GREASE_PENCIL",
                "VERTEX_GREASE_PENCIL", "SCULPT_GREASE_PENCIL"}


def _region_pixel(persmat: np.ndarray, width: int, height: int, point):
    clip = persmat @ np.array([*point, 1.0])
    if clip[3] <= 1e-9:
        return None
    return ((clip[0] / clip[3] + 1.0) * 0.5 * width, (clip[1] / clip[3] + 1.0) * 0.5 * height)


def overlay_discs(context, rv3d, width: int, height: int) -> list[tuple[float, float, float]]:
    """Where Blender draws the 3D cursor and the object origins in this region, (x, y, r) in region pixels: the
    composite keeps what Blender drew there on top of the splats. The cursor: a circle of half a widget unit and
    axis lines of one (overlay_cursor.hh), at its pixel; origins: dots of the theme's size, of the active and
    selected objects (all objects with Origins (All))."""
    ov = context.space_data.overlay
    if not ov.show_overlays or context.mode in _PAINT_MODES:
        return []
    prefs = context.preferences
    pixel = float(prefs.system.pixel_size)
    persmat = np.array(rv3d.window_matrix) @ np.array(rv3d.view_matrix)
    discs = []
    if ov.show_cursor:
        widget = round(18.0 * prefs.system.ui_scale) + 2.0 * pixel  # U.widget_unit
        xy = _region_pixel(persmat, width, height, context.scene.cursor.location)
        if xy is not None:
            discs.append((math.floor(xy[0]) + 0.5, math.floor(xy[1]) + 0.5, widget + 2.0 * pixel))
    if ov.show_object_origins:
        active = context.view_layer.objects.active
        r = 0.5 * (prefs.themes[0].view_3d.object_origin_size + 1.0) * pixel + 1.5
        for obj in context.visible_objects:
            if obj == active or obj.select_get() or ov.show_object_origins_all:
                xy = _region_pixel(persmat, width, height, obj.matrix_world.translation)
                if xy is not None:
                    discs.append((xy[0], xy[1], r))
    return [d for d in discs if -d[2] <= d[0] <= width + d[2] and -d[2] <= d[1] <= height + d[2]][:MAX_DISCS]


def _snapshot(width: int, height: int) -> tuple:
    """The bound overlay layer's blue and alpha bytes (b + 256 a as floats: Blender's GPUTexture takes only float
    data) and window depth as textures, rows bottom first; and the raw colour and depth buffers."""
    import gpu
    fb = gpu.state.active_framebuffer_get()
    t0 = time.perf_counter()
    colour = fb.read_color(0, 0, width, height, 4, 0, "UBYTE")  # waits for the GPU to finish Blender's drawing
    t1 = time.perf_counter()
    depth = fb.read_depth(0, 0, width, height)
    t2 = time.perf_counter()
    pairs = np.frombuffer(colour, np.uint16)  # little-endian: r + 256 g, b + 256 a per pixel
    rg = np.ascontiguousarray(pairs[0::2], np.float32)
    ba = np.ascontiguousarray(pairs[1::2], np.float32)
    t3 = time.perf_counter()
    snap = tuple(gpu.types.GPUTexture((width, height), format="R32F", data=gpu.types.Buffer("FLOAT", x.size, x))
                 for x in (rg, ba))
    dtex = gpu.types.GPUTexture((width, height), format="R32F", data=depth)
    t4 = time.perf_counter()
    timing.update(read_colour_ms=(t1 - t0) * 1e3, read_depth_ms=(t2 - t1) * 1e3, pack_ms=(t3 - t2) * 1e3,
                  upload_ms=(t4 - t3) * 1e3)
    return snap, dtex, colour, depth


def _composite(context, rv3d, region, quads: list, settings, names=()) -> bool:
    """Draw the splat images with the composite shader; False when it cannot (too many objects, or their images
    land differently): the caller draws the plain quads."""
    if len(quads) > MAX_LAYERS or any(q[2] != quads[0][2] or q[3] != quads[0][3] for q in quads):
        return False
    w, h = region.width, region.height
    t0 = time.perf_counter()
    snap, depth, colour_buf, depth_buf = _snapshot(w, h)
    t1 = time.perf_counter()
    params = composite_params(rv3d.window_matrix, rv3d.view_matrix, w, h, viewport_background(context),
                              grid_normal(context.space_data, rv3d), overlay_discs(context, rv3d, w, h))
    layers = [(q[0], q[1]) for q in quads]
    draw_composite(snap, depth, layers, quads[0][2], quads[0][3], params)
    timing.update(snapshot_ms=(t1 - t0) * 1e3, composite_ms=(time.perf_counter() - t1) * 1e3)
    if capture.pop("next", False):
        import gpu
        out = gpu.state.active_framebuffer_get().read_color(0, 0, w, h, 4, 0, "UBYTE")
        capture.update(size=(w, h), colour=np.frombuffer(colour_buf, np.uint8).reshape(h, w, 4).copy(),
                       depth=np.frombuffer(depth_buf, np.float32).reshape(h, w).copy(),
                       out=np.frombuffer(out, np.uint8).reshape(h, w, 4).copy(), params=params,
                       shading=quads[0][3], time=time.monotonic(), objects=list(names))
    return True


def draw_callback() -> None:
    global last_error
    context = bpy.context
    settings = getattr(context.scene, "gs_ibl_overlay", None)
    rv3d, region = context.region_data, context.region
    if settings is None or not settings.show or rv3d is None or region is None:
        return
    try:
        t0 = time.perf_counter()
        view, window = np.array(rv3d.view_matrix), np.array(rv3d.window_matrix)
        eye = np.linalg.inv(view)[:3, 3]
        objs = [o for o in context.visible_objects if is_mesh_splats(o)]  # Blender draws its native splats itself
        objs.sort(key=lambda o: -np.linalg.norm(np.array(o.matrix_world.translation) - eye))  # far first
        slot = region.as_pointer()
        now = time.monotonic()
        scale = _motion.scale(slot, view_key(view, window, region.width, region.height), now,
                              settings.resolution_scale)
        ms, quads = 0.0, []
        for obj in objs:
            img = _image_now(obj, rv3d, region.width, region.height, scale, slot)
            if img is None:  # its splats are still being uploaded: nothing drawn of it yet
                continue
            ms += img.render_ms
            quads.append((*_textures_for((splat_cache.uid(obj), slot), img), img.view.ndc_rect,
                          shader_params(img.view, settings.exposure)))
        composited = bool(quads) and use_composite and _composite(context, rv3d, region, quads, settings,
                                                                     [o.name for o in objs])
        if quads and not composited:
            draw_quads(quads)
        _forget_undrawn(slot, {splat_cache.uid(o) for o in objs})
        draw_ms = (time.perf_counter() - t0) * 1e3
        last_draw[slot] = {"scale": scale, "render_ms": ms, "draw_ms": draw_ms, "objects": len(objs), "time": now,
                           "composited": composited, "objects_drawn": [o.name for o in objs]}
        draw_log.append((now, slot, scale, ms, draw_ms))
        _schedule_refine(now)
        last_error = None
    except Exception as e:  # noqa: BLE001  a draw handler that raises would print on every redraw
        if str(e) != last_error:
            print(f"GS-IBL overlay: {e}")
        last_error = str(e)


def last_images(context, region, rv3d) -> list[tuple]:
    """(object, OverlayImage) of the splat objects drawn in this region, as last drawn there (rendered again if the
    view changed since): what the mouse points at."""
    settings = context.scene.gs_ibl_overlay
    slot = region.as_pointer()
    scale = last_draw.get(slot, {}).get("scale", settings.resolution_scale)
    images = [(o, _image_now(o, rv3d, region.width, region.height, scale, slot, wait=True))
              for o in context.visible_objects if is_mesh_splats(o)]
    return [(o, img) for o, img in images if img is not None]


def splats_under_mouse(context, x: float, y: float):
    """The nearest splat object whose overlay image covers region pixel (x, y), with the hit (overlay_math
    .SplatHit), or None (Show Splats off, no splats there)."""
    settings = getattr(context.scene, "gs_ibl_overlay", None)
    region, rv3d = context.region, context.region_data
    if settings is None or not settings.show or region is None or rv3d is None:
        return None
    view, window = np.array(rv3d.view_matrix), np.array(rv3d.window_matrix)
    best = None
    for obj, img in last_images(context, region, rv3d):
        hit = splat_hit(img, view, window, region.width, region.height, x, y, OPAQUE_CUT)
        if hit is not None and (best is None or hit.distance < best[1].distance):
            best = (obj, hit)
    return best


def _schedule_refine(now: float) -> None:
    """One timer redraws the viewports when a region drawn coarse while moving has been still long enough."""
    global _refine_scheduled
    wait = _motion.refine_in(now)
    if wait is None or _refine_scheduled:
        return
    _refine_scheduled = True
    bpy.app.timers.register(_refine, first_interval=max(wait, 0.02))


def _refine() -> float | None:
    global _refine_scheduled
    wait = _motion.refine_in(time.monotonic())
    if wait is not None and wait > 0.0:
        return wait  # the view moved again meanwhile: wait for it to settle
    _refine_scheduled = False
    if wait is not None:
        tag_redraw()
    return None


def tag_redraw() -> None:
    wm = bpy.context.window_manager
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def hide_helpers(show: bool) -> int:
    """While the overlay shows, splat objects draw nothing of their own; afterwards their point proxy is back.

    In Blender 5.x the lines and points of its overlays (an object's bounds, the black dots of a mesh's loose
    vertices) are drawn over POST_VIEW drawing whatever its depth, so a display type cannot hide them: the proxy's
    Fraction goes to 0 instead (no points, and the mesh's own vertices are not drawn while the modifier replaces
    them). The previous fraction is kept on the object. splat_cache is told that the geometry update Blender
    reports for this is not an edit, so nothing is uploaded again. Returns how many objects changed.
    """
    changed = 0
    for obj in bpy.data.objects:
        if obj.library is not None or (HIDDEN_KEY in obj.keys()) == show:
            continue  # linked (not ours to edit), or already as wanted: the depsgraph handler calls this often
        mod = obj.modifiers.get(PROXY_MODIFIER) if is_splat_object(obj) else None
        if mod is None or mod.node_group is None:
            continue
        fraction = modifier_input_identifiers(mod.node_group).get("Fraction")
        if fraction is None:
            continue
        if show and HIDDEN_KEY not in obj.keys():
            obj[HIDDEN_KEY] = float(get_modifier_input(mod, fraction))
            set_modifier_input(mod, fraction, 0.0)
        elif not show and HIDDEN_KEY in obj.keys():
            set_modifier_input(mod, fraction, float(obj[HIDDEN_KEY]))
            del obj[HIDDEN_KEY]
        else:
            continue
        splat_cache.proxy_switched(obj)
        changed += 1
    return changed


def show_changed(settings, context) -> None:
    """Show Splats toggled: helpers hidden or restored, images freed when off (the uploaded splats stay)."""
    global _motion
    hide_helpers(settings.show)
    _motion = ViewMotion()  # views that changed while hidden are drawn at full resolution at once
    if not settings.show:
        clear_cache()
    tag_redraw()


def display_changed(settings, context) -> None:
    """Resolution or Exposure changed: only the image is redrawn (the texture follows the exposure)."""
    tag_redraw()


@persistent
def _on_depsgraph_update(scene, depsgraph) -> None:
    # A splat object imported or appended while the overlay shows is hidden like the others.
    settings = getattr(scene, "gs_ibl_overlay", None)
    if settings is not None and settings.show:
        hide_helpers(True)


def register_overlay() -> None:
    """The draw handler, the depsgraph handler, and the click operators with their keymap items (picking.py)."""
    global _handle
    from . import picking
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")
    if _on_depsgraph_update not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(_on_depsgraph_update)
    for cls in picking.CLASSES:
        if not getattr(cls, "is_registered", False):
            bpy.utils.register_class(cls)
    picking.register_keymaps()


def unregister_overlay() -> None:
    global _handle, _refine_scheduled, _shader, _composite_shader, _dummy
    from . import picking
    picking.unregister_keymaps()
    for cls in reversed(picking.CLASSES):
        if getattr(cls, "is_registered", False):
            bpy.utils.unregister_class(cls)
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    while _on_depsgraph_update in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_on_depsgraph_update)
    if _refine_scheduled and bpy.app.timers.is_registered(_refine):
        bpy.app.timers.unregister(_refine)
    _refine_scheduled = False
    _shader = _composite_shader = _dummy = None
    clear_cache()
    try:
        hide_helpers(False)  # a disabled extension leaves the point proxies showing
    except (AttributeError, RuntimeError):  # data not accessible while Blender quits
        pass
