"""The Principled BSDF's tables (core/bsdf_tables.py) against the values Cycles' own tables
give, and the texture layout brdf.glsl reads; the World's harmonics (core/world_light.py)
against a direct integration.

Cycles' reference values (its precomputed ``ggx_E``, ``ggx_Eavg`` and
``ggx_gen_schlick_ior_s`` read with ``lookup_table_read``) are Monte Carlo estimates; the
quadrature here matches them to 0.2 %.
"""
import numpy as np
import pytest

from csm_engine.core import bsdf_tables, world_light


def test_tables_match_cycles_values():
    t = bsdf_tables.tables()
    assert bsdf_tables.lookup(t["e"], 0.5, 1.0) == pytest.approx(0.91528, rel=2e-3)
    assert bsdf_tables.lookup(t["e_avg"], 1.0) == pytest.approx(0.40914, rel=2e-3)
    z = np.sqrt((1.5 - 1.0) / (1.5 + 1.0))
    assert bsdf_tables.lookup(t["s_ior"], z, 0.5, 0.4) == pytest.approx(0.0639, rel=0.02)
    # A mirror reflects everything it is shown (E = 1); a rough lobe seen from above loses
    # energy to masking and shadowing.
    assert np.allclose(t["e"][0], 1.0) and t["e"][-1, -1] < 0.35


def test_texture_layout_holds_the_tables_where_the_shader_reads_them():
    t = bsdf_tables.tables()
    image = bsdf_tables.lut_texture_rows()
    assert image.shape == (bsdf_tables.LUT_HEIGHT, bsdf_tables.LUT_WIDTH, 4)
    n = bsdf_tables.S_SIZE
    k, i, j = 5, 3, 7                       # z slice, roughness node, cos node
    texel = image[bsdf_tables.S_IOR_ROW + j, k * n + i]
    assert texel[0] == pytest.approx(t["s_ior"][k, i, j]) and \
        texel[1] == pytest.approx(t["s_ior"][k + 1, i, j])
    texel = image[bsdf_tables.E_ROW + j, i]
    assert texel[:3] == pytest.approx([t["e"][i, j], t["s5"][i, j], t["e_avg"][i]])
    names = dict(bsdf_tables.glsl_defines())
    assert int(names["BSDF_LUT_E_ROW"]) == bsdf_tables.E_ROW


def test_world_harmonics_give_the_irradiance_of_a_smooth_world():
    d = world_light.equirect_directions(128, 256)
    radiance = (1.0 + 0.5 * d[..., 2] + 0.3 * d[..., 0] ** 2)[..., None] * np.ones(3)
    coefficients = world_light.radiance_sh(radiance)
    latitude = np.pi * ((np.arange(128) + 0.5) / 128 - 0.5)
    solid_angle = (2 * np.pi / 256) * (np.pi / 128) * np.cos(latitude)[:, None]
    for normal in ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, -0.8]):
        cos = np.clip(d @ np.array(normal), 0.0, None)
        direct = float((cos * solid_angle * radiance[..., 0]).sum())
        assert world_light.irradiance(coefficients, normal)[0] == pytest.approx(direct,
                                                                               rel=0.01)
    uniform = world_light.uniform_sh((0.3, 0.2, 0.1))
    assert world_light.irradiance(uniform, [0.0, 0.6, 0.8]) == \
        pytest.approx(np.pi * np.array([0.3, 0.2, 0.1]), rel=1e-4)


def test_shipped_tables_are_the_quadratures():
    """data/bsdf_tables.npz (read instead of computing at the first render) holds what the
    quadrature computes now, to float32 rounding: regenerate it with
    ``bsdf_tables.write_tables_file()`` after changing the quadrature."""
    import numpy as np
    fresh = bsdf_tables.compute_tables()
    with np.load(bsdf_tables.TABLES_FILE) as shipped:
        for name, values in fresh.items():
            np.testing.assert_allclose(shipped[name], values, rtol=0, atol=1e-6,
                                       err_msg=name)
    assert bsdf_tables.tables()["e"].dtype == np.float64
