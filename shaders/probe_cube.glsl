// Cube-map conventions of gs_ibl_addon/core/cubemap.py, for the probe filters (keep the two in step):
// faces +X,-X,+Y,-Y,+Z,-Z; texel (i, j) of N: dir = forward + s*right + t*down, s = 2(i+0.5)/N - 1, t likewise.
// Cubes live in storage buffers as packed RGB floats, index ((face * N + j) * N + i) * 3.

const vec3 FACE_FWD[6] = vec3[6](vec3(1, 0, 0), vec3(-1, 0, 0), vec3(0, 1, 0), vec3(0, -1, 0), vec3(0, 0, 1), vec3(0, 0, -1));
const vec3 FACE_RIGHT[6] = vec3[6](vec3(0, 0, -1), vec3(0, 0, 1), vec3(1, 0, 0), vec3(1, 0, 0), vec3(1, 0, 0), vec3(-1, 0, 0));
const vec3 FACE_DOWN[6] = vec3[6](vec3(0, -1, 0), vec3(0, -1, 0), vec3(0, 0, 1), vec3(0, 0, -1), vec3(0, -1, 0), vec3(0, -1, 0));

vec3 texel_dir(uint face, uint i, uint j, uint n) {
    float s = 2.0 * (float(i) + 0.5) / float(n) - 1.0;
    float t = 2.0 * (float(j) + 0.5) / float(n) - 1.0;
    return normalize(FACE_FWD[face] + s * FACE_RIGHT[face] + t * FACE_DOWN[face]);
}

// Face of a direction with numpy.argmax's tie-break (first largest axis), and (s, t) on that face.
uint dir_face(vec3 d, out float s, out float t) {
    vec3 a = abs(d);
    uint axis = (a.x >= a.y && a.x >= a.z) ? 0u : (a.y >= a.z ? 1u : 2u);
    uint face = axis * 2u + (d[axis] < 0.0 ? 1u : 0u);
    float depth = dot(d, FACE_FWD[face]);
    s = dot(d, FACE_RIGHT[face]) / depth;
    t = dot(d, FACE_DOWN[face]) / depth;
    return face;
}

#ifdef PROBE_CUBE_BUFFER
// Needs: a buffer array PROBE_CUBE_BUFFER of packed RGB floats; PROBE_CUBE_OFFSET (float index of the cube).
vec3 cube_texel(uint face, int i, int j, uint n) {
    uint idx = PROBE_CUBE_OFFSET + ((face * n + uint(j)) * n + uint(i)) * 3u;
    return vec3(PROBE_CUBE_BUFFER[idx], PROBE_CUBE_BUFFER[idx + 1u], PROBE_CUBE_BUFFER[idx + 2u]);
}

vec3 cube_nearest(vec3 d, uint n) {
    float s, t;
    uint face = dir_face(d, s, t);
    int i = clamp(int((s + 1.0) * 0.5 * float(n)), 0, int(n) - 1);
    int j = clamp(int((t + 1.0) * 0.5 * float(n)), 0, int(n) - 1);
    return cube_texel(face, i, j, n);
}

// Off-face texel (one coordinate outside 0..N-1): nearest texel along its extrapolated centre direction.
vec3 cube_neighbour(uint face, int i, int j, uint n) {
    float s = 2.0 * (float(i) + 0.5) / float(n) - 1.0;
    float t = 2.0 * (float(j) + 0.5) / float(n) - 1.0;
    return cube_nearest(FACE_FWD[face] + s * FACE_RIGHT[face] + t * FACE_DOWN[face], n);
}

// Seamless tap, as probe/sampling.py::_texel_lookup: a corner tap is the mean of the three texels meeting there.
// Written as loops over taps (not four inlined calls) to keep the code small: lavapipe compiles it on first use.
vec3 cube_tap(uint face, int i, int j, uint n) {
    int last = int(n) - 1;
    bool iin = i >= 0 && i <= last;
    bool jin = j >= 0 && j <= last;
    int ic = clamp(i, 0, last), jc = clamp(j, 0, last);
    if (iin && jin) return cube_texel(face, i, j, n);
    bool corner = !iin && !jin;
    vec3 acc = corner ? cube_texel(face, ic, jc, n) : vec3(0.0);
    int taps = corner ? 2 : 1;
    for (int k = 0; k < taps; ++k) {
        int ii = (corner && k == 1) ? ic : i;
        int jj = corner ? (k == 0 ? jc : j) : j;
        acc += cube_neighbour(face, ii, jj, n);
    }
    return corner ? acc / 3.0 : acc;
}

vec3 cube_bilinear(vec3 d, uint n) {
    float s, t;
    uint face = dir_face(d, s, t);
    float x = (s + 1.0) * 0.5 * float(n) - 0.5;
    float y = (t + 1.0) * 0.5 * float(n) - 0.5;
    int i0 = int(floor(x)), j0 = int(floor(y));
    float fx = x - float(i0), fy = y - float(j0);
    vec3 acc = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        int di = k & 1, dj = k >> 1;
        float w = (di == 1 ? fx : 1.0 - fx) * (dj == 1 ? fy : 1.0 - fy);
        acc += w * cube_tap(face, i0 + di, j0 + dj, n);
    }
    return acc;
}
#endif
