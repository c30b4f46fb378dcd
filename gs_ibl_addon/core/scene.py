"""The in-memory splat scene every stage after file reading works on.

Values are *activated* (what the renderer uses), not the raw values stored in a 3DGS PLY:
opacity is sigmoid(raw), scale is exp(raw), rotation is a unit quaternion (w, x, y, z).
Colour is kept as SH coefficients exactly as 3DGS stores them: ``sh[:, 0]`` is f_dc, and the
evaluated colour toward direction d is ``c = SH_C0 * sh[:, 0] + 0.5 + sum_l>0 Y_lm(d) * sh[:, k]``, and the light
it stands for depends on the scene's ``colour_space`` (core/colour.py): srgb_to_linear(c) for "srgb" (captures
trained on photos, Blender's rule, the default for files from outside), max(c, 0) for "linear".
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .colour import check_colour_space, linear_sh_for_srgb_rule
from .sh import C0 as SH_C0  # re-exported: the degree-0 colour rule's constant, under its 3DGS name
from .sh import coeff_count, degree_of
from .sh_rotation import rotate_sh

# Relative spread of a transform's singular values below which its scale counts as uniform (float32 matrices
# from Blender carry ~1e-7 noise; a deliberate non-uniform scale differs by far more).
UNIFORM_SCALE_RTOL = 1e-4


def rgb_to_sh_dc(rgb: np.ndarray) -> np.ndarray:
    """Inverse of the degree-0 colour rule: the f_dc (float32) that renders as ``rgb``."""
    return (np.asarray(rgb, np.float32) - 0.5) / SH_C0


def sh_dc_to_rgb(dc: np.ndarray) -> np.ndarray:
    """The degree-0 colour rule, unclamped, in float64: ``0.5 + SH_C0 * f_dc``."""
    return 0.5 + SH_C0 * np.asarray(dc, np.float64)


@dataclass
class SplatScene:
    positions: np.ndarray  # (N, 3) float32, scene units
    scales: np.ndarray  # (N, 3) float32, > 0 (activated: exp of the PLY value)
    rotations: np.ndarray  # (N, 4) float32 unit quaternions (w, x, y, z)
    opacities: np.ndarray  # (N,) float32 in (0, 1) (activated: sigmoid of the PLY value)
    sh: np.ndarray  # (N, (degree+1)^2, 3) float32; [:, 0] is f_dc, [:, 1:] the f_rest in 3DGS order
    source: str = "<memory>"  # file it came from, for messages
    repairs: dict[str, int] = field(default_factory=dict)  # what reading repaired, with counts
    colour_space: str = "srgb"  # what SH + 0.5 means (core/colour.py): "srgb" (trained on photos) or "linear"

    def __post_init__(self) -> None:
        check_colour_space(self.colour_space, f"{self.source}: colour space")
        n = len(self.positions)
        for name, arr, shape in (
            ("positions", self.positions, (n, 3)),
            ("scales", self.scales, (n, 3)),
            ("rotations", self.rotations, (n, 4)),
            ("opacities", self.opacities, (n,)),
        ):
            if arr.shape != shape:
                raise ValueError(f"{self.source}: {name} has shape {arr.shape}, expected {shape}")
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3:
            raise ValueError(f"{self.source}: sh has shape {self.sh.shape}, expected (N, K, 3)")
        if self.sh.shape[1] not in (1, 4, 9, 16):
            raise ValueError(f"{self.source}: {self.sh.shape[1]} SH coefficients per channel; expected 1, 4, 9 or 16")

    @property
    def count(self) -> int:
        return len(self.positions)

    @property
    def sh_degree(self) -> int:
        return degree_of(self.sh.shape[1])

    def with_sh_degree(self, degree: int) -> "SplatScene":
        """The same splats with SH truncated (or zero-padded) to ``degree``."""
        k = coeff_count(degree)
        sh = np.zeros((self.count, k, 3), np.float32)
        m = min(k, self.sh.shape[1])
        sh[:, :m] = self.sh[:, :m]
        return SplatScene(self.positions, self.scales, self.rotations, self.opacities, sh, self.source,
                          dict(self.repairs), self.colour_space)

    def subset(self, index: np.ndarray) -> "SplatScene":
        return SplatScene(self.positions[index], self.scales[index], self.rotations[index], self.opacities[index],
                          self.sh[index], self.source, dict(self.repairs), self.colour_space)

    def transformed(self, matrix: np.ndarray) -> "SplatScene":
        """Splats moved by a 4x4 similarity transform (rotation, uniform scale, translation).

        A non-uniform scale or a mirror raises ValueError saying what to do: lin / cbrt(det) is then no rotation,
        and using it would silently give the splats wrong shapes.
        View-dependent colour (SH bands 1-3) turns with the splats (core/sh_rotation.py), so a rotated object, a
        glTF node transform and an import's axis conversion all show each splat's colour toward the same side of it.
        """
        m = np.asarray(matrix, np.float64)
        lin = m[:3, :3]
        s = _uniform_scale(lin, self.source)
        r = lin / s
        pos = self.positions.astype(np.float64) @ lin.T + m[:3, 3]
        q = quat_multiply(matrix_to_quat(r), self.rotations.astype(np.float64))
        sh = self.sh
        if sh.shape[1] > 1 and not np.allclose(r, np.identity(3), atol=1e-7):  # unrotated: no copy of the SH
            u, _, vt = np.linalg.svd(r)  # the nearest rotation: a float32 matrix is orthonormal only to ~1e-5
            sh = rotate_sh(sh, u @ vt)
        return SplatScene(pos.astype(np.float32), (self.scales * s).astype(np.float32), q.astype(np.float32),
                          self.opacities, sh, self.source, dict(self.repairs), self.colour_space)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if self.count == 0:
            return np.zeros(3, np.float32), np.zeros(3, np.float32)
        return self.positions.min(0), self.positions.max(0)

    @staticmethod
    def empty() -> "SplatScene":
        return SplatScene(np.zeros((0, 3), np.float32), np.ones((0, 3), np.float32),
                          np.zeros((0, 4), np.float32), np.zeros((0,), np.float32), np.zeros((0, 1, 3), np.float32))


def combine_scenes(scenes: list[SplatScene], source: str | None = None) -> SplatScene:
    """One scene of ``scenes`` (sorted together by whatever renders it: a room and a capture standing in it): SH
    padded to the highest degree; a mix of colour spaces is drawn by Blender's rule (sRGB), linear scenes re-encoded
    for it (colour.linear_sh_for_srgb_rule: exact for the base colour, the view-dependent bands to first order)."""
    space = scenes[0].colour_space if len({s.colour_space for s in scenes}) == 1 else "srgb"
    deg = max(s.sh_degree for s in scenes)
    parts = []
    for s in scenes:
        s = s.with_sh_degree(deg)
        if s.colour_space != space:
            s = SplatScene(s.positions, s.scales, s.rotations, s.opacities, linear_sh_for_srgb_rule(s.sh),
                           source=s.source, colour_space=space)
        parts.append(s)
    return SplatScene(*(np.concatenate([getattr(s, f) for s in parts]) for f in
                        ("positions", "scales", "rotations", "opacities", "sh")),
                      source=source or ", ".join(s.source for s in scenes), colour_space=space)


def _uniform_scale(lin: np.ndarray, source: str) -> float:
    """The factor s of a 3x3 map lin = s * R (R a rotation); ValueError naming the problem otherwise."""
    # Not "apply the scale": in Blender that would move the splat centres and leave their stored sizes behind.
    advice = ("splats support rotation, translation and uniform scale only: give the object the same scale on all "
              "three axes, with no negative factor")
    if not np.all(np.isfinite(lin)):
        raise ValueError(f"{source}: the transform has NaN or infinite entries; give the object a finite transform")
    sv = np.linalg.svd(lin, compute_uv=False)
    if not sv[-1] > 0:
        raise ValueError(f"{source}: the transform is degenerate (a zero scale flattens the splats); "
                         "give the object a non-zero scale")
    if sv[0] - sv[-1] > UNIFORM_SCALE_RTOL * sv[0]:
        factors = ", ".join(f"{f:.4g}" for f in np.linalg.norm(lin, axis=0))
        raise ValueError(f"{source}: the transform scales non-uniformly (x, y, z factors {factors}); {advice}")
    if np.linalg.det(lin) < 0:
        raise ValueError(f"{source}: the transform mirrors (negative determinant: a negative scale); {advice}")
    return float(np.cbrt(np.linalg.det(lin)))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (w, x, y, z) -> (N, 3, 3) rotation matrices."""
    q = np.asarray(q, np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """A single 3x3 rotation matrix -> unit quaternion (w, x, y, z)."""
    r = np.asarray(r, np.float64)
    t = np.trace(r)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k]) * 2
        q = [0.0] * 4
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.array(q)
    return q / np.linalg.norm(q)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a*b, broadcasting (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, np.float64), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], -1)
