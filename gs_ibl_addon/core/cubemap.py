"""Cube-face and lat-long conventions: the one place where texels become directions.

Faces are ordered +X, -X, +Y, -Y, +Z, -Z with the Vulkan/OpenGL orientation: for face texel
(column i, row j, row 0 at the top) of an N x N face, s = 2(i+0.5)/N - 1 and t = 2(j+0.5)/N - 1, and the
(unnormalised) direction is ``forward + s * right + t * down`` with the bases in FACE_BASES. Directions are
in the scene's world space (Blender: Z up). Every filter and the renderer read these functions.

Lat-long images use Blender's equirectangular mapping (the Environment Texture node): the centre column
looks along +X, u = 0.25 along +Y, the top row is +Z:  u = 0.5 - atan2(y, x) / (2 pi), v_top = acos(z) / pi.
"""
from __future__ import annotations

import functools

import numpy as np

FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")

# (forward, right, down) per face: direction = forward + s*right + t*down (OpenGL cube map table).
FACE_BASES = np.array([
    [[1, 0, 0], [0, 0, -1], [0, -1, 0]],
    [[-1, 0, 0], [0, 0, 1], [0, -1, 0]],
    [[0, 1, 0], [1, 0, 0], [0, 0, 1]],
    [[0, -1, 0], [1, 0, 0], [0, 0, -1]],
    [[0, 0, 1], [1, 0, 0], [0, -1, 0]],
    [[0, 0, -1], [-1, 0, 0], [0, -1, 0]],
], dtype=np.float64)
FACE_BASES.flags.writeable = False  # its rows are the cube views' own arrays (render/views.py _cube_views)


def face_st(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel-centre coordinates s (columns) and t (rows) in (-1, 1), each shaped (size, size)."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    t, s = np.meshgrid(c, c, indexing="ij")
    return s, t


def face_directions(size: int) -> np.ndarray:
    """(6, size, size, 3) unit directions of every texel centre."""
    s, t = face_st(size)
    f, r, d = FACE_BASES[:, 0], FACE_BASES[:, 1], FACE_BASES[:, 2]
    v = f[:, None, None, :] + s[None, ..., None] * r[:, None, None, :] + t[None, ..., None] * d[:, None, None, :]
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _corner_area(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Solid angle of the face rectangle from (0,0) to (x,y) on the plane at distance 1 (exact).
    return np.arctan2(x * y, np.sqrt(x * x + y * y + 1.0))


@functools.lru_cache(maxsize=16)
def _texel_solid_angles(size: int) -> np.ndarray:
    e = np.linspace(-1.0, 1.0, size + 1)
    x0, x1 = e[:-1][None, :], e[1:][None, :]
    y0, y1 = e[:-1][:, None], e[1:][:, None]
    w = _corner_area(x0, y0) - _corner_area(x0, y1) - _corner_area(x1, y0) + _corner_area(x1, y1)
    w.flags.writeable = False  # shared by every caller
    return w


def texel_solid_angles(size: int) -> np.ndarray:
    """(size, size) exact solid angle of each texel (the same for every face; the six faces sum to 4 pi). Cached
    (read-only): filters and face resizes ask for the same few sizes on every bake."""
    return _texel_solid_angles(int(size))


def direction_to_face(dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 3) directions -> (face index, s, t) with s, t in [-1, 1] as in face_st."""
    d = np.asarray(dirs, np.float64)
    a = np.abs(d)
    axis = np.argmax(a, axis=-1)
    neg = np.take_along_axis(d, axis[..., None], -1)[..., 0] < 0
    face = axis * 2 + neg
    f, r, dn = FACE_BASES[face, 0], FACE_BASES[face, 1], FACE_BASES[face, 2]
    depth = np.sum(d * f, -1)
    s = np.sum(d * r, -1) / depth
    t = np.sum(d * dn, -1) / depth
    return face, s, t


def sample_cube_nearest(cube: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Nearest-texel lookup of a (6, N, N, C) cube along (..., 3) directions."""
    n = cube.shape[1]
    face, s, t = direction_to_face(dirs)
    i = np.clip(((s + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    j = np.clip(((t + 1) * 0.5 * n).astype(np.int64), 0, n - 1)
    return cube[face, j, i]


def latlong_directions(width: int, height: int) -> np.ndarray:
    """(height, width, 3) unit directions of lat-long texel centres in Blender's equirectangular mapping."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    phi = (0.5 - u) * 2.0 * np.pi  # azimuth: atan2(y, x)
    theta = v * np.pi  # from +Z
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    st = np.sin(th)
    return np.stack([st * np.cos(ph), st * np.sin(ph), np.cos(th)], -1)


def edge_neighbours(size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every border texel of every face, its neighbour across the cube edge, and its neighbour inward.

    Returns three (M, 3) int arrays of (face, row, column). Comparing the first pair measures a seam; the
    second pair is the same step inside a face, the yardstick for what a seam-free difference looks like.
    """
    n = size
    idx = np.arange(n)
    sides = [  # (rows, cols, inward step (drow, dcol))
        (np.zeros(n, int), idx, (1, 0)), (np.full(n, n - 1), idx, (-1, 0)),
        (idx, np.zeros(n, int), (0, 1)), (idx, np.full(n, n - 1), (0, -1)),
    ]
    s, t = face_st(n)
    edge, across, inward = [], [], []
    for face in range(6):
        f, r, d = FACE_BASES[face]
        for rows, cols, (dr, dc) in sides:
            ss, tt = s[rows, cols], t[rows, cols]
            # one texel outward, beyond the face's edge
            so, to = ss - dc * 2.0 / n, tt - dr * 2.0 / n
            dirs = f[None] + so[:, None] * r[None] + to[:, None] * d[None]
            fa, sa, ta = direction_to_face(dirs)
            ia = np.clip(((sa + 1) * 0.5 * n).astype(int), 0, n - 1)
            ja = np.clip(((ta + 1) * 0.5 * n).astype(int), 0, n - 1)
            edge.append(np.stack([np.full(n, face), rows, cols], 1))
            across.append(np.stack([fa, ja, ia], 1))
            inward.append(np.stack([np.full(n, face), rows + dr, cols + dc], 1))
    return np.concatenate(edge), np.concatenate(across), np.concatenate(inward)


def seam_ratio(cube: np.ndarray) -> float:
    """Mean colour step across cube edges over the mean step one texel inward: about 1 without seams."""
    e, a, i = edge_neighbours(cube.shape[1])
    rgb = cube[..., :3]
    across = np.abs(rgb[e[:, 0], e[:, 1], e[:, 2]] - rgb[a[:, 0], a[:, 1], a[:, 2]]).mean()
    inward = np.abs(rgb[e[:, 0], e[:, 1], e[:, 2]] - rgb[i[:, 0], i[:, 1], i[:, 2]]).mean()
    return float(across / max(inward, 1e-12))
