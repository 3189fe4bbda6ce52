"""Inverses of the few small matrices a frame needs, without LAPACK.

NOTE: ``np.linalg.inv`` solves through OpenBLAS's ``gesv``, which hands even a 3x3 to its
thread pool. On the two-core benchmark machine, when other processes (or llvmpipe's
rasteriser threads) hold both cores, one such call waited up to 4 ms for a pool thread:
a camera-only viewport redraw went from 3.3 to 13 ms with two busy processes beside it.
These closed forms never leave the calling thread. numpy only.
"""

import numpy as np

from .memo import ArrayMemo

_IDENTITY3 = np.eye(3)
_IDENTITY3.setflags(write=False)
_BOTTOM_ROW = (0.0, 0.0, 0.0, 1.0)
# How far R @ R.T may be from the identity for R to count as a rotation: float64 matrices
# from Blender's float32 ones are orthonormal to ~1e-7; anything off by more (scale, shear)
# takes the general inverse.
_RIGID_TOLERANCE = 1e-6


def inverse_transpose_3x3(a):
    """``inv(a).T`` of a 3x3 (the matrix that carries normals): its cofactors over its
    determinant. Raises ``np.linalg.LinAlgError`` for a singular ``a``, as inv does."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = np.asarray(a, dtype=np.float64).tolist()
    c00, c01, c02 = a11 * a22 - a12 * a21, a12 * a20 - a10 * a22, a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    if not np.isfinite(det) or det == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    return np.array([[c00, c01, c02],
                     [a02 * a21 - a01 * a22, a00 * a22 - a02 * a20, a01 * a20 - a00 * a21],
                     [a01 * a12 - a02 * a11, a02 * a10 - a00 * a12, a00 * a11 - a01 * a10]]) / det


def inverse_rigid(m):
    """Inverse of a 4x4 rotation-and-translation (a camera's or a view's world matrix):
    the rotation transposed, the translation turned back. Any other matrix (scaled,
    sheared, projective) gets the general inverse."""
    m = np.asarray(m, dtype=np.float64)
    rotation = m[:3, :3]
    if tuple(m[3]) != _BOTTOM_ROW or \
            np.abs(rotation @ rotation.T - _IDENTITY3).max() > _RIGID_TOLERANCE:
        return np.linalg.inv(m)
    out = np.empty((4, 4))
    out[:3, :3] = rotation.T
    out[:3, 3] = -(rotation.T @ m[:3, 3])
    out[3] = _BOTTOM_ROW
    return out


# The lens does not change while the view moves: its inverse is kept per lens.
inverse_projection = ArrayMemo(np.linalg.inv, 16)
inverse_projection.__doc__ = "``inv(clip_from_view)``, kept per lens (read-only array)."
