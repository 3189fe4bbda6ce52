"""The World's light as spherical harmonics: what the lighting pass needs of a World that is
not one colour.

Owns the real spherical harmonics up to band 2 (9 coefficients; ``sh_basis``), the
projection of an equirectangular environment image onto them with Blender's Environment
Texture mapping (``radiance_sh``), the coefficients of a uniform World (``uniform_sh``),
and the irradiance they give a surface (``irradiance``, for tests and tools: the shader
evaluates the same sum). A uniform World of radiance L gives exactly the irradiance pi L
whatever the normal, so such Worlds keep their exposure. numpy only, pure.
"""

import numpy as np

SH_COUNT = 9
# Clamped-cosine convolution per band (Ramamoorthi and Hanrahan 2001): irradiance
# E(n) = sum over coefficients of BAND_IRRADIANCE[band] * L_i * Y_i(n).
BAND_IRRADIANCE = (np.pi, 2.0 * np.pi / 3.0, np.pi / 4.0)
BAND_OF = (0, 1, 1, 1, 2, 2, 2, 2, 2)
# Environment images larger than this (rows) are read at every k-th pixel: the second
# band cannot tell the difference.
MAX_ROWS = 128


def sh_basis(directions):
    """The 9 real spherical harmonics (..., 9) at unit ``directions`` (..., 3): Y00, then
    Y1-1, Y10, Y11 (y, z, x), then band 2 (xy, yz, 3z^2 - 1, xz, x^2 - y^2)."""
    d = np.asarray(directions, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([
        np.full_like(x, 0.282095),
        0.488603 * y, 0.488603 * z, 0.488603 * x,
        1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3.0 * z * z - 1.0),
        1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=-1)


def equirect_directions(height, width):
    """World directions (height, width, 3) at the pixel centres of an equirectangular
    image whose row 0 is the bottom (as Blender's pixels are), with Blender's Environment
    Texture mapping: u = atan2(y, -x) / 2pi + 0.5, v = latitude / pi + 0.5."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    theta = 2.0 * np.pi * (u - 0.5)
    latitude = np.pi * (v - 0.5)
    cos_lat = np.cos(latitude)[:, None]
    return np.stack([-np.cos(theta)[None, :] * cos_lat,
                     np.sin(theta)[None, :] * cos_lat,
                     np.broadcast_to(np.sin(latitude)[:, None], (height, width))], axis=-1)


def radiance_sh(rgb):
    """(9, 3) coefficients of the radiance of an equirectangular environment image
    (height, width, 3; linear; row 0 at the bottom), integrated over the sphere with each
    pixel's solid angle."""
    rgb = np.asarray(rgb, dtype=np.float64)[..., :3]
    step = max(1, int(np.ceil(rgb.shape[0] / MAX_ROWS)))
    rgb = rgb[step // 2::step, step // 2::step]
    height, width = rgb.shape[:2]
    directions = equirect_directions(height, width)
    latitude = np.pi * ((np.arange(height) + 0.5) / height - 0.5)
    solid_angle = (2.0 * np.pi / width) * (np.pi / height) * np.cos(latitude)
    basis = sh_basis(directions) * solid_angle[:, None, None]
    return np.einsum("hwk,hwc->kc", basis, rgb)


def uniform_sh(color):
    """(9, 3) coefficients of a uniform radiance ``color`` (rgb)."""
    coefficients = np.zeros((SH_COUNT, 3))
    coefficients[0] = np.asarray(color, dtype=np.float64)[:3] * (4.0 * np.pi * 0.282095)
    return coefficients


def irradiance(coefficients, normals):
    """Irradiance (..., 3) on surfaces of unit ``normals`` (..., 3) from a World of
    radiance ``coefficients`` (9, 3)."""
    weights = np.array([BAND_IRRADIANCE[band] for band in BAND_OF])
    return sh_basis(normals) @ (np.asarray(coefficients) * weights[:, None])
