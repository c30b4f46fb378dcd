"""Box/mip filtering: solid-angle-weighted 2x2 downsampling, mip chains, and the thesis's fast irradiance.

The thesis's "box filter" downsamples the radiance cube (512 -> 32 per face) and reads the small cube by
normal. That is an average of radiance over a small patch around n, not the cosine-weighted hemisphere
integral: exact for a uniform environment, too sharp otherwise unless the cube is taken down to a couple
of texels per face (then the patch is a whole face, and the answer is coarse instead). ``box_irradiance``
reproduces it with a selectable final face size, so the error can be measured against the exact reference
(see tests/test_probe_filters.py for the numbers).
"""
from __future__ import annotations

import numpy as np

from .. import cubemap
from .sampling import check_cube, sample_cube_bilinear


def downsample_cube(cube: np.ndarray) -> np.ndarray:
    """(6, N, N, C) -> (6, N/2, N/2, C): each parent is the solid-angle-weighted mean of its 2x2 children."""
    return downsample_faces(check_cube(cube))


def downsample_faces(faces: np.ndarray) -> np.ndarray:
    """downsample_cube for any number of cube faces (K, N, N, C): the texel weights are the same on every face."""
    a = np.asarray(faces)
    k, n = a.shape[0], a.shape[1]
    if n % 2:
        raise ValueError(f"cannot halve a cube with odd face size {n}")
    w = cubemap.texel_solid_angles(n)[None, :, :, None]
    num = (a * w).reshape(k, n // 2, 2, n // 2, 2, a.shape[3]).sum(axis=(2, 4))
    den = np.broadcast_to(w, (1, n, n, 1)).reshape(1, n // 2, 2, n // 2, 2, 1).sum(axis=(2, 4))
    return num / den


def faces_to_size(faces: np.ndarray, target: int) -> np.ndarray:
    """(K, N, N, C) faces at face size ``target`` (N and target powers of two): each target texel the
    solid-angle-weighted mean of the texels it covers, in one step (what halving repeatedly gives: the parents'
    weights are their children's sums), or doubled by bilinear interpolation (no detail is made up)."""
    from ..tolerance import upsample2
    a = np.asarray(faces)
    k, n, c = a.shape[0], a.shape[1], a.shape[3]
    if n > target:
        f = n // target
        w = cubemap.texel_solid_angles(n)
        num = np.einsum("kiajbc,iajb->kijc", a.reshape(k, target, f, target, f, c),
                        w.reshape(target, f, target, f), dtype=np.float64)
        return num / w.reshape(target, f, target, f).sum(axis=(1, 3))[None, :, :, None]
    a = np.asarray(a, np.float64)
    while a.shape[1] < target:
        a = upsample2(a)
    return a


def halving_sizes(size: int, target: int = 1) -> list[int]:
    """Face sizes a 2x2 downsampling chain goes through from ``size``: [size, size/2, ...], halved while the face
    is above ``target`` and even. Every mip chain and downsample-to-size (numpy and GPU) follows this list."""
    sizes = [int(size)]
    while sizes[-1] > target and sizes[-1] % 2 == 0:
        sizes.append(sizes[-1] // 2)
    return sizes


def downsample_to_size(cube: np.ndarray, target: int) -> np.ndarray:
    """downsample_cube repeated along halving_sizes(face size, target): the last (smallest) level only."""
    small = check_cube(cube)
    for _ in halving_sizes(small.shape[1], target)[1:]:
        small = downsample_cube(small)
    return small


def mip_chain(cube: np.ndarray, min_size: int = 1) -> list[np.ndarray]:
    """[cube, cube/2, ...] down to min_size per face (halving stops at an odd size)."""
    mips = [check_cube(cube)]
    for _ in halving_sizes(mips[0].shape[1], min_size)[1:]:
        mips.append(downsample_cube(mips[-1]))
    return mips


def box_level_size(face_size: int, size: int, level_size: int | None) -> int:
    """The face size the box filter reads from (default: the output size), checked to be face_size / 2^k."""
    level = size if level_size is None else level_size
    n = face_size
    if level < 1 or n % level or (n // level) & (n // level - 1):
        raise ValueError(f"box filter: level size {level} must be the face size {n} divided by a power of 2")
    return level


def box_irradiance(cube: np.ndarray, size: int, level_size: int | None = None) -> np.ndarray:
    """Thesis box filter: downsample to level_size per face (default: size), read bilinearly by normal.

    Returns (6, size, size, C). level_size must be the input size divided by a power of two.
    """
    a = check_cube(cube)
    small = downsample_to_size(a, box_level_size(a.shape[1], size, level_size))
    return sample_cube_bilinear(small, cubemap.face_directions(size))
