// Splat maths shared by preprocess and emit; mirrors gs_ibl_addon/core/render/splat_math.py.
#include "common.glsl"

// The View struct (one per view of a batch) is declared in gs_ibl_addon/core/vk/constants.py VIEW_ROWS and
// generated into constants.glsl: a pixel (px, py) of view v is the frame's pixel (px + x0, py + y0), at
// image-plane coordinates view_s / view_t.
float view_s(View v, uint px) {
    return ((float(px + v.extra.z) + 0.5) / v.grid.z * 2.0 - 1.0) * v.right_tanx.w + v.grid.x;
}
float view_t(View v, uint py) {
    return ((float(py + v.extra.w) + 0.5) / v.grid.w * 2.0 - 1.0) * v.down_tany.w + v.grid.y;
}

// TILE, MAX_VIEWS, PREP (vec4s per prepared splat) and DEPTH_KEY_SHIFT come from constants.glsl.
const float DILATION_PX2 = 0.3;

mat3 quat_to_mat(vec4 q) {  // q = (w, x, y, z), unit; returns columns
    float w = q.x, x = q.y, y = q.z, z = q.w;
    return mat3(
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y),
        2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x),
        2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y));
}

// Squared dilated scales: 3DGS's 0.3 px^2 screen-space low-pass, as a 3D isotropic variance at this distance.
vec3 dilated_scale2(vec3 s, float dist, float dilation_angle) {
    float d = dilation_angle * dist;
    return s * s + vec3(DILATION_PX2 * d * d);
}

// Tiles of view v touched by the ellipsoid {x : (x - mu)^T cov^-1 (x - mu) <= 1} (mu relative to the origin).
// Tight bounds from the tangent planes through the origin (the projected quadric); the whole view when the
// ellipsoid straddles the plane through the origin facing the view. Returns false when it touches no tile.
bool view_rect(View v, vec3 mu, mat3 cov, out uvec4 rect) {
    vec3 f = v.fwd.xyz;
    vec3 cf = cov * f;
    float z = dot(f, mu);
    float ff = dot(f, cf);
    if (z + sqrt(max(ff, 0.0)) <= 0.0) return false;
    uint tx = v.dims.z, ty = v.extra.y;
    vec3 r = v.right_tanx.xyz, dn = v.down_tany.xyz;
    // The view's rectangle of the image plane (an off-centre frame, a window of it): s in [sl, sh], t in [tl, th]
    float gw = v.grid.z, gh = v.grid.w, tnx = v.right_tanx.w, tny = v.down_tany.w;
    float sl = (float(v.extra.z) / gw * 2.0 - 1.0) * tnx + v.grid.x;
    float sh = (float(v.extra.z + v.dims.x) / gw * 2.0 - 1.0) * tnx + v.grid.x;
    float tl = (float(v.extra.w) / gh * 2.0 - 1.0) * tny + v.grid.y;
    float th = (float(v.extra.w + v.dims.y) / gh * 2.0 - 1.0) * tny + v.grid.y;
    // Outside one of the four side planes of the view's frustum (all through the origin): touches nothing.
    vec3 planes[4] = vec3[4](sh * f - r, r - sl * f, th * f - dn, dn - tl * f);
    for (int k = 0; k < 4; ++k) {
        vec3 n = planes[k];
        if (dot(n, mu) + sqrt(max(dot(n, cov * n), 0.0)) < 0.0) return false;
    }
    float a = ff - z * z;
    if (a >= -1e-6 * z * z) { rect = uvec4(0u, 0u, tx, ty); return true; }
    float x = dot(r, mu), y = dot(dn, mu);
    float bx = dot(r, cf) - x * z, cx = dot(r, cov * r) - x * x;
    float by = dot(dn, cf) - y * z, cy = dot(dn, cov * dn) - y * y;
    float sx = sqrt(max(bx * bx - a * cx, 0.0)), sy = sqrt(max(by * by - a * cy, 0.0));
    // a < 0: the roots (b -+ sqrt(disc)) / a are the two tangent slopes, smaller first.
    vec2 ux = vec2(bx + sx, bx - sx) / a, uy = vec2(by + sy, by - sy) / a;
    // in the view's pixels (pixel i spans [i, i + 1]), half a pixel wider
    float w = float(v.dims.x), h = float(v.dims.y);
    vec2 fx = ((ux - v.grid.x) / tnx + 1.0) * 0.5 * gw - float(v.extra.z);
    vec2 fy = ((uy - v.grid.y) / tny + 1.0) * 0.5 * gh - float(v.extra.w);
    float px0 = fx.x - 0.5, px1 = fx.y + 0.5, py0 = fy.x - 0.5, py1 = fy.y + 0.5;
    if (px1 < 0.0 || py1 < 0.0 || px0 > w || py0 > h) return false;
    uint x0 = uint(max(px0, 0.0)) / TILE, y0 = uint(max(py0, 0.0)) / TILE;
    uint x1 = min(uint(min(px1, w)) / TILE + 1u, tx), y1 = min(uint(min(py1, h)) / TILE + 1u, ty);
    if (x0 >= x1 || y0 >= y1) return false;
    rect = uvec4(x0, y0, x1, y1);
    return true;
}

// The ellipsoid beyond which the splat's alpha falls below 1/255: cutoff * Sigma'.
mat3 cut_covariance(mat3 rot, vec3 s2, float cutoff) {
    mat3 rs = mat3(rot[0] * s2.x, rot[1] * s2.y, rot[2] * s2.z);
    return cutoff * (rs * transpose(rot));
}

// A direction as two floats (the octahedral map), precise to float rounding in every direction: the raster's plane
// forms take a splat's centre ray from it, which the whitened origin o' would give only to |mu| / scale times that.
vec2 octahedral(vec3 v) {
    vec3 n = v / (abs(v.x) + abs(v.y) + abs(v.z));
    if (n.z >= 0.0) return n.xy;
    return (1.0 - abs(n.yx)) * vec2(n.x >= 0.0 ? 1.0 : -1.0, n.y >= 0.0 ? 1.0 : -1.0);
}

vec3 from_octahedral(vec2 e) {  // not normalised
    vec3 n = vec3(e, 1.0 - abs(e.x) - abs(e.y));
    if (n.z < 0.0) n.xy = (1.0 - abs(n.yx)) * vec2(n.x >= 0.0 ? 1.0 : -1.0, n.y >= 0.0 ? 1.0 : -1.0);
    return n;
}
