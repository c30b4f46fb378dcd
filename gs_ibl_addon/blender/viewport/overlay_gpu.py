"""The overlay's drawing on Blender's GPU module: its shaders, the splat images as textures, the passes that draw them.

The composite pass (overlay_math.composite is its numpy reference) reads back what Blender drew in the overlay layer
and the scene depth (_snapshot), then writes splats and scene together, nearest first, up to MAX_LAYERS objects;
draw_quads is the plain depth-tested fallback for more objects. Nothing here decides what to draw: overlay.py does.
"""
from __future__ import annotations

import time

import numpy as np

from ...core.colour import linear_to_srgb
from .overlay_math import (BACKGROUND_KINDS, COVERAGE_EPS, DEPTH_PULL, EDGE_REACH, GRID_TOLERANCE, LINE_CUT,
                           LINE_REACH, MAX_LAYERS)

ALPHA_CUT = 1.0 / 255.0  # fragments with less coverage are not drawn
OPAQUE_CUT = 0.5  # the depth pass writes the depth of pixels at least this covered; picking's opaque enough
MAX_DISCS = 64  # cursor and origin discs kept on top of the splats

_shader = None
_composite_shader = None
_dummy = None
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


def free() -> None:
    """Drop the shaders and the dummy textures (the extension is unregistered; Blender may be quitting)."""
    global _shader, _composite_shader, _dummy
    _shader = _composite_shader = _dummy = None
