"""What keeps a stabilized cascade still while the camera moves.

Owns the exact ``bounding_sphere`` of a frustum slice (its radius does not change when the
camera turns), ``round_up_radius`` and the dyadic rounding that turn radii and texel sizes
into coarse, exactly representable steps, and the light-space texel grid the boxes snap to
(``snap_to_texel_grid``, ``texel_grid_position``). numpy only.
"""

import math
from itertools import combinations
from types import MappingProxyType

import numpy as np

from ..checks import finite
from ..memo import ArrayMemo


def _circumcentres(points, subsets):
    """Centre and radius of the smallest sphere through each subset of points (the
    circumcentre inside the subset's affine hull); ``ok`` is False for degenerate ones."""
    base = points[subsets[:, 0]]                                     # (S, 3)
    spans = points[subsets[:, 1:]] - base[:, None, :]                # (S, k-1, 3)
    gram = spans @ np.swapaxes(spans, 1, 2)                          # (S, k-1, k-1)
    rhs = 0.5 * np.einsum("skk->sk", gram)
    scale = np.maximum(np.einsum("skk->s", gram), 1e-300)
    ok = np.abs(np.linalg.det(gram)) > 1e-10 * scale ** gram.shape[1]
    gram = np.where(ok[:, None, None], gram, np.eye(gram.shape[1]))
    weights = np.linalg.solve(gram, rhs[..., None])[..., 0]          # (S, k-1)
    centres = base + np.einsum("sk,skd->sd", weights, spans)
    radii = np.linalg.norm(centres - base, axis=1)
    return centres, radii, ok


def _subsets(size):
    subsets = np.array(list(combinations(range(8), size)))
    subsets.setflags(write=False)
    return subsets


_SUBSETS = MappingProxyType({size: _subsets(size) for size in (2, 3, 4)})


def bounding_sphere(points):
    """The smallest sphere enclosing up to 8 points: (centre (3,), radius).

    Exact: the minimal sphere is the circumsphere of 2, 3 or 4 of the points, so every such
    subset is tried (162 candidates for 8 points, batched) and the smallest one that holds
    all points wins. Depends only on the points' relative positions, so a rigidly moved or
    turned slice gets the same radius.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.shape != (8, 3) or not np.all(np.isfinite(points)):
        raise ValueError(f"bounding_sphere needs 8 finite 3D points, got shape {points.shape}")
    # NOTE: work relative to the centroid so that a slice far from the world origin keeps
    # its full precision in the subtractions below.
    origin = points.mean(axis=0)
    local = points - origin
    best_centre, best_radius = np.zeros(3), np.inf
    extent = np.abs(local).max()
    for size in (2, 3, 4):
        centres, radii, ok = _circumcentres(local, _SUBSETS[size])
        distance = np.linalg.norm(local[None, :, :] - centres[:, None, :], axis=2)
        holds = ok & np.all(distance <= radii[:, None] * (1.0 + 1e-9) + 1e-12 * extent, axis=1)
        if np.any(holds & (radii < best_radius)):
            index = np.flatnonzero(holds)[np.argmin(radii[holds])]
            best_centre, best_radius = centres[index], radii[index]
    # The tolerance above may accept a sphere a hair too small; use the true farthest point.
    best_radius = float(np.linalg.norm(local - best_centre, axis=1).max())
    return best_centre + origin, best_radius


# View-space slice corners -> their bounding sphere. The corners depend only on the
# projection and the split distances, so a viewport redraw where only the camera moves
# asks for the same spheres again; the exact search above costs ~0.5 ms a cascade.
_VIEW_SPHERES_MAX = 64
_view_space_sphere = ArrayMemo(bounding_sphere, 64)


def round_up_radius(radius):
    """Round a cascade's sphere radius up to a step of 1/64 of its leading power of two
    (e.g. 1/64 unit for radii 1..2, 1/4 unit for 16..32).

    NOTE: the sphere radius is constant while the camera turns only up to floating-point
    noise; a texel size that changed in the last bit would rescale the whole shadow map and
    make it shimmer. Rounding up to a coarse, exactly representable step removes the noise.
    A step relative to the radius (not Babylon's fixed 1/16 unit) keeps tiny scenes sharp
    and costs at most ~1.6% of the resolution.
    """
    radius = finite("sphere radius", radius)
    if not radius > 0.0:
        raise ValueError(f"sphere radius must be above 0, got {radius}")
    return _round_up_dyadic(radius * (1.0 + 1e-12), bits=7)


def _round_up_dyadic(value, bits):
    """Smallest number >= value with at most ``bits`` significant binary digits."""
    step = 2.0 ** (math.floor(math.log2(value)) - (bits - 1))
    return math.ceil(value / step) * step


def snap_to_texel_grid(value, texel_size):
    """Round light-space coordinates to the nearest whole multiple of ``texel_size``."""
    return np.round(np.asarray(value, dtype=np.float64) / texel_size) * texel_size


def texel_grid_position(cascade):
    """Where the cascade's box centre sits on the light-space texel grid, in texels (x, y).

    For a stabilized cascade these are whole numbers: the box only ever moves by whole
    texels, which is what keeps shadow edges still. Compare two frames' positions to see
    how many texels the box moved.
    """
    # light_from_world's translation is minus the box centre in the light's rotated frame.
    return -cascade.light_from_world[:2, 3] / cascade.texel_size_world

