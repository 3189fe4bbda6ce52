"""The tables the Principled BSDF reads (brdf.glsl), computed in numpy.

Owns the GGX tables Cycles' Principled BSDF uses for direct light and layering, computed
here by quadrature over the GGX distribution of visible normals (Heitz 2018,
``compute_tables``), and their packing into one float texture (``lut_texture_rows``):

- ``E(roughness, cos)``: the directional albedo of single-scattering GGX with Fresnel 1
  (Cycles' ``ggx_E``, 32 x 32), and ``E_avg(roughness)``, its cosine-weighted mean over the
  hemisphere (``ggx_Eavg``): the multiple-scattering energy compensation;
- ``s_ior(roughness, cos, z)``: where the real dielectric Fresnel of IOR
  eta = (1 + z^2) / (1 - z^2), averaged over the lobe, lies between F0 and 1
  (``ggx_gen_schlick_ior_s``, 16^3): the specular layer's albedo, taken out of the
  diffuse layer beneath it;
- ``s_schlick5(roughness, cos)``: the same for Schlick's (1 - cos)^5
  (``ggx_gen_schlick_s`` at exponent 5): a metal's albedo; on E's 32 x 32 grid (Cycles
  keeps it on 16 x 16), so that one texel holds E, E_avg and it.

Table axes run over [0, 1] with nodes at i / (n - 1), read with linear interpolation as
Cycles' ``lookup_table_read`` does; roughness is Principled Roughness (alpha = r^2), cos
the cosine between the shading normal and the view. The quadrature takes ~0.7 s here, a
first render's worth, so its result ships as ``data/bsdf_tables.npz`` (written by
``write_tables_file``; a unit test recomputes it and compares) and is read from there,
once per process (``ValueMemo``); without the file the tables are computed. numpy only.
"""

import os

import numpy as np

from .memo import ValueMemo
from .paths import PACKAGE_DIR

TABLES_FILE = os.path.join(PACKAGE_DIR, "data", "bsdf_tables.npz")

E_SIZE = 32          # E, E_avg, s_schlick5: roughness x cos
S_SIZE = 16          # s_ior: roughness x cos x z
QUADRATURE = 48      # visible-normal samples per axis (midpoints of a regular grid)
# The texture (RGBA floats, LUT_WIDTH x LUT_HEIGHT), laid out so that a bilinear read of
# four texels gives several tables at once (the lighting pass pays per fetch):
# - rows S_IOR_ROW.. (cos), column z * S_SIZE + roughness: (s_ior at z slice k, s_ior at
#   slice k + 1, 0, 0), so one read interpolates between two slices;
# - rows E_ROW.. (cos), column roughness: (E, s_schlick5, E_avg, 0).
LUT_WIDTH = S_SIZE * S_SIZE
S_IOR_ROW = 0
E_ROW = S_IOR_ROW + S_SIZE
LUT_HEIGHT = E_ROW + E_SIZE
# The cosine of a view at the horizon's node, kept off 0 where the lobe degenerates.
MIN_COS = 1e-4


def f0_from_ior(eta):
    """Reflectance at normal incidence of a dielectric of IOR ``eta``."""
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def ior_from_f0(f0):
    """The IOR whose normal-incidence reflectance is ``f0`` (clamped to 0..0.99), as
    Principled's Specular IOR Level does."""
    root = np.sqrt(np.clip(f0, 0.0, 0.99))
    return (1.0 + root) / (1.0 - root)


def ior_from_z(z):
    """The IOR of the s_ior table's z axis, z = sqrt((eta - 1) / (eta + 1)) (clamped to
    1e-4 .. 0.99 as Cycles' tables are)."""
    z2 = np.square(np.clip(z, 1e-4, 0.99))
    return (1.0 + z2) / (1.0 - z2)


def fresnel_dielectric(cos_i, eta):
    """Unpolarized Fresnel reflectance of a dielectric of relative IOR ``eta`` > 1."""
    c = np.abs(cos_i)
    g = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def _lambda(alpha2, cos):
    tan2 = np.maximum(1.0 / np.square(cos) - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha2 * tan2) - 1.0)


def _lobe_samples(roughness, cos_view):
    """For each (roughness, cos_view) pair (broadcast), the quadrature's weights
    G2 / G1(view) (0 where the reflected direction falls below the horizon) and
    cos(half vector, view), each (..., N^2): the mean of the weights is the lobe's albedo
    (E), and the mean of f(cos) where the weight is not 0 the Fresnel f averaged over the
    visible normals as Cycles' tables average it (each sample's eval with F over its eval
    with F = 1)."""
    roughness = np.asarray(roughness, dtype=np.float64)[..., None]
    mu = np.maximum(np.asarray(cos_view, dtype=np.float64), MIN_COS)[..., None]
    alpha = np.square(np.maximum(roughness, 1e-4))
    u = (np.arange(QUADRATURE) + 0.5) / QUADRATURE
    u1, u2 = (a.ravel() for a in np.meshgrid(u, u, indexing="ij"))
    # The view in the stretched (alpha = 1) configuration, and a basis around it.
    vx, vz = np.sqrt(1.0 - mu * mu), mu
    sx, sz = alpha * vx, vz
    norm = np.sqrt(sx * sx + sz * sz)
    sx, sz = sx / norm, sz / norm
    # T1 = (0, 1, 0) x ... : with the view in the xz plane, T1 = (0, 1, 0) up to sign.
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    t1 = r * np.cos(phi)
    t2 = r * np.sin(phi)
    s = 0.5 * (1.0 + sz)
    t2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - t1 * t1, 0.0)) + s * t2
    tn = np.sqrt(np.maximum(1.0 - t1 * t1 - t2 * t2, 0.0))
    # H_ = t1 * T1 + t2 * T2 + tn * V_, with T1 = (0, 1, 0) and T2 = V_ x T1 rotated:
    # T2 = (-sz, 0, sx) (perpendicular to V_ in the xz plane).
    hx = t2 * (-sz) + tn * sx
    hy = t1 * np.ones_like(sx)
    hz = t2 * sx + tn * sz
    hx, hy, hz = alpha * hx, alpha * hy, np.maximum(hz, 0.0)
    norm = np.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx / norm, hy / norm, hz / norm
    cos_hv = hx * vx + hz * vz
    lz = 2.0 * cos_hv * hz - vz
    alpha2 = alpha * alpha
    lambda_v = _lambda(alpha2, mu)
    lambda_l = _lambda(alpha2, np.maximum(lz, 1e-7))
    weight = np.where(lz > 0.0, (1.0 + lambda_v) / (1.0 + lambda_v + lambda_l), 0.0)
    return weight, np.clip(cos_hv, 0.0, 1.0)


def compute_tables():
    """The tables by quadrature (what ``data/bsdf_tables.npz`` holds), float64."""
    nodes_e = np.linspace(0.0, 1.0, E_SIZE)
    rough, mu = np.meshgrid(nodes_e, nodes_e, indexing="ij")      # [roughness, cos]
    weight, cos_e = _lobe_samples(rough, mu)
    e = weight.mean(axis=-1)                                       # [roughness, cos]
    s5 = ((weight > 0.0) * (1.0 - cos_e) ** 5).mean(axis=-1)
    # E_avg = 2 * integral of E(cos) cos dcos, by Gauss-Legendre over cos.
    x, w = np.polynomial.legendre.leggauss(24)
    cos_g = 0.5 * (x + 1.0)
    weight_g, _ = _lobe_samples(nodes_e[:, None], cos_g[None, :])
    e_avg = (weight_g.mean(axis=-1) * cos_g * w).sum(axis=-1)      # 2 * 0.5 * sum
    nodes_s = np.linspace(0.0, 1.0, S_SIZE)
    rough_s, mu_s = np.meshgrid(nodes_s, nodes_s, indexing="ij")
    weight_s, cos_hv = _lobe_samples(rough_s, mu_s)                # [roughness, cos, N]
    valid = weight_s > 0.0
    s_ior = np.empty((S_SIZE, S_SIZE, S_SIZE))                     # [z, roughness, cos]
    for k, z in enumerate(nodes_s):
        eta = ior_from_z(z)
        f0 = f0_from_ior(eta)
        s = np.clip((fresnel_dielectric(cos_hv, eta) - f0) / (1.0 - f0), 0.0, 1.0)
        s_ior[k] = (valid * s).mean(axis=-1)
    return dict(e=e, e_avg=e_avg, s_ior=s_ior, s5=s5)


_SHAPES = (("e", (E_SIZE, E_SIZE)), ("e_avg", (E_SIZE,)),
           ("s_ior", (S_SIZE, S_SIZE, S_SIZE)), ("s5", (E_SIZE, E_SIZE)))


def _tables_uncached():
    try:
        with np.load(TABLES_FILE) as shipped:
            loaded = {name: np.array(shipped[name], dtype=np.float64)
                      for name, _shape in _SHAPES}
    except (OSError, KeyError, ValueError):
        return compute_tables()
    if any(loaded[name].shape != shape for name, shape in _SHAPES):
        return compute_tables()
    return loaded


def write_tables_file(path=TABLES_FILE):
    """Write the quadrature's tables to ``path`` (float32, as the texture holds them)."""
    tables_now = compute_tables()
    np.savez_compressed(path, **{name: tables_now[name].astype(np.float32)
                                 for name, _shape in _SHAPES})


_tables = ValueMemo(_tables_uncached, 1, key=lambda: ())


def tables():
    """{"e": [roughness, cos] (32 x 32), "e_avg": [roughness] (32),
    "s_ior": [z, roughness, cos] (16^3), "s5": [roughness, cos] (32 x 32)}, read-only."""
    return _tables()


def lut_texture_rows():
    """The tables packed into one (LUT_HEIGHT, LUT_WIDTH, 4) float32 image, rows bottom
    first as a texture holds them (layout: the ``*_ROW`` constants; brdf.glsl reads it)."""
    t = tables()
    image = np.zeros((LUT_HEIGHT, LUT_WIDTH, 4), dtype=np.float32)
    for k in range(S_SIZE):
        columns = slice(k * S_SIZE, (k + 1) * S_SIZE)
        image[S_IOR_ROW:S_IOR_ROW + S_SIZE, columns, 0] = t["s_ior"][k].T
        image[S_IOR_ROW:S_IOR_ROW + S_SIZE, columns, 1] = t["s_ior"][min(k + 1, S_SIZE - 1)].T
    image[E_ROW:E_ROW + E_SIZE, :E_SIZE, 0] = t["e"].T
    image[E_ROW:E_ROW + E_SIZE, :E_SIZE, 1] = t["s5"].T
    image[E_ROW:E_ROW + E_SIZE, :E_SIZE, 2] = t["e_avg"][None, :]
    return image


def glsl_defines():
    """The texture layout as ``#define``s for brdf.glsl: BSDF_LUT_E_ROW, ..."""
    return [("BSDF_LUT_S_IOR_ROW", str(S_IOR_ROW)), ("BSDF_LUT_E_ROW", str(E_ROW)),
            ("BSDF_LUT_E_SIZE", str(E_SIZE)), ("BSDF_LUT_S_SIZE", str(S_SIZE))]


def lookup(table, *coordinates):
    """Linear interpolation in ``table`` at coordinates in [0, 1] per axis (nodes at
    i / (n - 1)), as Cycles' lookup_table_read."""
    table = np.asarray(table, dtype=np.float64)
    result = table
    for axis_coordinate in coordinates:
        n = result.shape[0]
        x = float(np.clip(axis_coordinate, 0.0, 1.0)) * (n - 1)
        i = min(int(x), n - 1)
        j = min(i + 1, n - 1)
        t = x - i
        result = (1.0 - t) * result[i] + t * result[j]
    return float(result)
