"""Where the view depth is cut into cascades, and how big each cascade's map is.

Owns ``split_distances`` (uniform, logarithmic, the course's hybrid formula, or manual
distances), ``manual_splits_from_fractions`` (the settings' fractions of the shadow
distance as distances), ``cascade_resolutions`` (texels per cascade) and
``blend_band_widths`` (how far before each split the next cascade fades in), with the
checks of a cascade count and of a resolution (which fitting shares).
numpy only.
"""

import math
import operator

import numpy as np

from ..checks import finite
from ..frame_layout import MAX_CASCADES, SPLIT_SCHEMES

MIN_CASCADE_RESOLUTION = 64          # texels; halving stops here (see cascade_resolutions)


def _count(count):
    try:
        if isinstance(count, bool):
            raise TypeError
        count = operator.index(count)
    except TypeError:
        raise ValueError(f"cascade count must be a whole number 1..{MAX_CASCADES}, "
                         f"got {count!r}") from None
    if not 1 <= count <= MAX_CASCADES:
        raise ValueError(f"cascade count must be 1..{MAX_CASCADES}, got {count}")
    return count


def _resolution(name, value):
    try:
        if isinstance(value, bool):
            raise TypeError
        value = operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be a whole number of texels, got {value!r}") from None
    if value < 1:
        raise ValueError(f"{name} must be at least 1 texel, got {value}")
    return value


def split_distances(near, far, count, scheme, lam=0.5, manual=None):
    """View depths (scene units) bounding each cascade: an array of ``count + 1`` values.

    ``result[0] == near`` and ``result[-1] == far`` exactly; cascade ``i`` covers view
    depths ``result[i] .. result[i+1]``. Schemes (``i = 0..N``, ``N = count``):

    - ``'UNIFORM'``: ``z_i = n + (i/N) (f - n)``; equal depth ranges (sharp far away,
      blurry near the camera).
    - ``'LOG'``: ``z_i = n (f/n)^(i/N)``; logarithmic, i.e. each slice is the same ratio
      deeper, which gives even texel density on screen. Needs ``near > 0``.
    - ``'HYBRID'``: the course's formula
      ``z_i = lam n (f/n)^(i/N) + (1 - lam) (n + (i/N) (f - n))``;
      ``lam = 0`` is uniform, ``lam = 1`` is logarithmic. Needs ``near > 0`` when ``lam > 0``.
    - ``'MANUAL'``: ``manual`` holds the ``count - 1`` interior distances in scene units,
      strictly increasing and strictly inside ``(near, far)`` (see
      ``manual_splits_from_fractions`` for the settings' fractions).

    Raises ``ValueError`` naming the bad value.
    """
    near, far = finite("near distance", near), finite("far distance", far)
    count = _count(count)
    if not isinstance(scheme, str) or scheme.upper() not in SPLIT_SCHEMES:
        raise ValueError(f"split scheme must be one of {', '.join(SPLIT_SCHEMES)}, "
                         f"got {scheme!r}")
    scheme = scheme.upper()
    if not far > near:
        raise ValueError(f"far distance ({far}) must be greater than near distance ({near})")
    lam = finite("split lambda", lam)
    if scheme == "HYBRID" and not 0.0 <= lam <= 1.0:
        raise ValueError(f"split lambda must be in 0..1, got {lam}")
    if scheme == "LOG":
        lam = 1.0
    elif scheme == "UNIFORM":
        lam = 0.0

    fraction = np.arange(count + 1, dtype=np.float64) / count
    if scheme == "MANUAL":
        interior = _manual_interior(near, far, count, manual)
        splits = np.concatenate([[near], interior, [far]])
    else:
        if lam > 0.0 and not near > 0.0:
            raise ValueError(f"the {scheme.lower()} split scheme needs a near distance above 0, "
                             f"got {near} (use the uniform scheme or raise the clip start)")
        uniform = near + fraction * (far - near)
        if lam > 0.0:
            logarithmic = near * (far / near) ** fraction
            splits = lam * logarithmic + (1.0 - lam) * uniform
        else:
            splits = uniform
    # NOTE: the formulas hit near and far only up to rounding ((f/n)^1 * n may differ from f
    # in the last bit). The shader compares view depth against these values, so the ends are
    # pinned exactly: nothing in front of the shadow distance may fall past the last cascade.
    splits[0], splits[-1] = near, far
    steps = np.diff(splits)
    if not np.all(steps > 0.0):
        bad = int(np.argmin(steps))
        raise ValueError(f"near ({near}) and far ({far}) are too close to split into {count} "
                         f"cascades: split {bad + 1} ({splits[bad + 1]}) does not exceed "
                         f"split {bad} ({splits[bad]})")
    return splits


def _manual_interior(near, far, count, manual):
    wanted = count - 1
    if manual is None:
        raise ValueError(f"manual splits need {wanted} interior distance(s), got none")
    values = np.atleast_1d(np.asarray(manual, dtype=np.float64)).ravel()
    if values.shape[0] != wanted:
        raise ValueError(f"manual splits need exactly {wanted} interior distance(s) for "
                         f"{count} cascades, got {values.shape[0]}: {values.tolist()}")
    previous_name, previous = "the near distance", near
    for index, value in enumerate(values):
        name = f"manual split {index + 1} ({value})"
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite")
        if not value > previous:
            raise ValueError(f"{name} must be greater than {previous_name} ({previous})")
        if not value < far:
            raise ValueError(f"{name} must be less than the far distance ({far})")
        previous_name, previous = f"manual split {index + 1}", value
    return values


def manual_splits_from_fractions(far, fractions, count):
    """Interior split distances (scene units) from the settings' fractions of the shadow
    distance: ``distance_i = fraction_i * far`` for the first ``count - 1`` fractions."""
    far = finite("shadow distance", far)
    count = _count(count)
    values = np.atleast_1d(np.asarray(fractions, dtype=np.float64)).ravel()
    if values.shape[0] < count - 1:
        raise ValueError(f"{count} cascades need {count - 1} manual split fraction(s), "
                         f"got {values.shape[0]}: {values.tolist()}")
    return values[:count - 1] * far


def cascade_resolutions(count, base_resolution=2048, equal_resolution=False):
    """Shadow-map size per cascade in texels: base, base/2, base/4, ... never below
    ``MIN_CASCADE_RESOLUTION`` (64, or the base itself when that is smaller); all equal
    to the base when ``equal_resolution``."""
    count = _count(count)
    base = _resolution("base resolution", base_resolution)
    if equal_resolution:
        return [base] * count
    floor = min(MIN_CASCADE_RESOLUTION, base)
    return [max(base >> index, floor) for index in range(count)]


def blend_band_widths(splits, blend_band):
    """Blend band per cascade (scene units): ``blend_band`` capped at half of that
    cascade's depth range, so a band never reaches back past the middle of its cascade.
    The last cascade has no band (0): the far fade handles the shadow distance."""
    splits = np.asarray(splits, dtype=np.float64)
    band = finite("blend band", blend_band)
    if band < 0.0:
        raise ValueError(f"blend band must not be negative, got {band}")
    widths = np.minimum(band, 0.5 * np.diff(splits))
    widths[-1] = 0.0
    return widths

