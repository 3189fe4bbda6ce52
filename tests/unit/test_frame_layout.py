"""core/frame_layout.py: std140 offsets, the generated GLSL, packing round trips, the enums
and limits given to GLSL as #defines, and pack_frame filling the frame block by name."""

import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from csm_engine.core import cascades, frame_layout, paths, settings_model
from csm_engine.core.frame import PointLight, SpotLight, Sun, spot_cone_cosines
from csm_engine.core.frame_layout import FRAME_LAYOUT, UniformLayout, glsl_defines
from csm_engine.core.shadow_plan import WINDOW_FROM_CLIP, ShadowPlan, ShadowTile, pack_frame

PACKAGE = Path(frame_layout.__file__).resolve().parents[1]
SHADERS = sorted(Path(paths.shaders_dir()).glob("*.glsl"))

INNER = UniformLayout("Inner", (
    ("a", "vec3", "a vec3"),
    ("b", "float", "packed into a's 4th slot"),
    ("c", "vec2", "next vec2 slot"),
))

OUTER = UniformLayout("Outer", (
    ("m", "mat4", "a matrix"),
    ("flag", "int", "an int"),
    ("v", "vec3", "aligned to 16 after the int"),
    ("s", "float", "in v's 4th slot"),
    ("w", "vec2", "8-aligned"),
    ("f", "float", "right after w"),
    ("items", INNER, 3, "array of structs"),
    ("arr", "float", 4, "scalar array: 16-byte stride"),
    ("tail", "vec3", "last member; the struct pads to 16"),
))


def offsets(layout):
    return {f.name: f.offset for f in layout.fields}


def test_std140_offsets_match_hand_computed_ones():
    assert offsets(INNER) == {"a": 0, "b": 12, "c": 16}
    assert INNER.size == 32 and INNER.alignment == 16     # 24 bytes padded to 16
    assert offsets(OUTER) == {"m": 0, "flag": 64, "v": 80, "s": 92, "w": 96, "f": 104,
                              "items": 112, "arr": 208, "tail": 272}
    assert OUTER.field("items").stride == 32
    assert OUTER.field("arr").stride == 16
    assert OUTER.size == 288


def test_a_vec3_after_a_scalar_starts_a_new_vec4_slot():
    layout = UniformLayout("T", (("x", "float", "x"), ("y", "vec3", "y"), ("z", "vec2", "z"),
                                 ("q", "vec2", "q"), ("r", "vec4", "r")))
    assert offsets(layout) == {"x": 0, "y": 16, "z": 32, "q": 40, "r": 48}
    assert layout.size == 64


def _parse_structs(text):
    """struct name -> [(type, name, count or None)] from GLSL text."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    structs = {}
    for name, body in re.findall(r"struct\s+(\w+)\s*\{(.*?)\};", text, flags=re.S):
        members = []
        for kind, member, count in re.findall(r"(\w+)\s+(\w+)\s*(?:\[(\d+)\])?\s*;", body):
            members.append((kind, member, int(count) if count else None))
        structs[name] = members
    return structs


@pytest.mark.parametrize("layout", [OUTER, FRAME_LAYOUT], ids=lambda l: l.type_name)
def test_generated_glsl_matches_the_table(layout):
    text = layout.glsl()
    structs = _parse_structs(text)
    assert list(structs) == [s.type_name for s in layout.structs()], "dependencies first, once"
    for struct in layout.structs():
        assert structs[struct.type_name] == [(f.glsl_type, f.name, f.count)
                                             for f in struct.fields]
        for f in struct.fields:
            assert f"@{f.offset}: {f.doc}" in text, "offset and meaning are in the GLSL"


def _random_values(layout, rng):
    values = {}
    for f in layout.fields:
        def one():
            if f.is_struct:
                return _random_values(f.kind, rng)
            if f.kind == "int":
                return int(rng.integers(-1000, 1000))
            if f.kind == "float":
                return float(np.float32(rng.normal()))
            if f.kind == "mat4":
                return rng.normal(size=(4, 4)).astype(np.float32)
            return rng.normal(size=int(f.kind[-1])).astype(np.float32)
        values[f.name] = one() if f.count is None else [one() for _ in range(f.count)]
    return values


def _assert_same(expected, actual, where=""):
    if isinstance(expected, dict):
        assert set(expected) == set(actual), where
        for key in expected:
            _assert_same(expected[key], actual[key], f"{where}.{key}")
    elif isinstance(expected, list):
        assert len(expected) == len(actual), where
        for i, (e, a) in enumerate(zip(expected, actual)):
            _assert_same(e, a, f"{where}[{i}]")
    else:
        assert np.array_equal(np.asarray(expected), np.asarray(actual)), where


@pytest.mark.parametrize("layout", [OUTER, FRAME_LAYOUT], ids=lambda l: l.type_name)
def test_pack_then_unpack_gives_every_field_back(layout):
    values = _random_values(layout, np.random.default_rng(7))
    data = layout.pack(values)
    assert data.dtype == np.float32 and data.nbytes == layout.size
    _assert_same(values, layout.unpack(data))


def test_packed_bytes_are_std140():
    m = np.arange(16, dtype=np.float32).reshape(4, 4)
    data = OUTER.pack({"m": m, "flag": -3, "v": (1, 2, 3), "s": 4.5,
                       "items": [{}, {"a": (7, 8, 9), "b": 10, "c": (11, 12)}],
                       "arr": [1, 2, 3, 4], "tail": (5, 6, 7)})
    assert list(data[0:4]) == [0, 4, 8, 12], "column-major: the first column comes first"
    assert data.view(np.int32)[64 // 4] == -3, "ints are stored as int32, not floats"
    assert list(data[80 // 4:96 // 4]) == [1, 2, 3, 4.5]
    second = (112 + 32) // 4
    assert list(data[second:second + 6]) == [7, 8, 9, 10, 11, 12]
    assert list(data[208 // 4:272 // 4:4]) == [1, 2, 3, 4]
    assert list(data[272 // 4:288 // 4]) == [5, 6, 7, 0]


def test_packing_mistakes_name_the_field():
    with pytest.raises(KeyError, match="no field 'nope'"):
        OUTER.pack({"nope": 1})
    with pytest.raises(IndexError, match="Outer.items: 4 values for an array of 3"):
        OUTER.pack({"items": [{}] * 4})
    with pytest.raises(ValueError, match="Outer.v: expected 3"):
        OUTER.pack({"v": (1, 2)})
    with pytest.raises(ValueError, match="Outer.flag: int field"):
        OUTER.pack({"flag": 1.5})
    with pytest.raises(ValueError, match="4x4"):
        OUTER.pack({"m": np.eye(3)})


def test_table_mistakes_are_refused():
    with pytest.raises(ValueError, match="one-line doc"):
        UniformLayout("T", (("x", "float", ""),))
    with pytest.raises(ValueError, match="reserved"):
        UniformLayout("T", (("filter", "float", "reserved word"),))
    with pytest.raises(ValueError, match="not one of"):
        UniformLayout("T", (("x", "dvec3", "no doubles"),))
    with pytest.raises(ValueError, match="named twice"):
        UniformLayout("T", (("x", "float", "x"), ("x", "int", "x")))


def test_frame_layout_fits_a_uniform_block_and_uses_the_limits():
    assert FRAME_LAYOUT.size % 16 == 0
    assert FRAME_LAYOUT.size <= 16384, "GL guarantees only 16 KB per uniform block"
    counts = {f.name: f.count for f in FRAME_LAYOUT.fields if f.count is not None}
    assert counts == {"cascades": frame_layout.MAX_CASCADES,
                      "shadow_tiles": frame_layout.MAX_SHADOW_TILES,
                      "point_lights": frame_layout.MAX_POINT_LIGHTS,
                      "spot_lights": frame_layout.MAX_SPOT_LIGHTS,
                      "world_sh": 9}


# ---- GLSL uses only what the table and glsl_defines provide ------------------------------

def _glsl_code(path):
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def test_every_frame_field_the_glsl_reads_is_in_the_table():
    used = 0
    for path in SHADERS:
        code = _glsl_code(path)
        for name, member in re.findall(r"\bframe\.(\w+)(?:\[[^\]]*\])?(?:\.(\w+))?", code):
            field = FRAME_LAYOUT.field(name)
            if field.is_struct and member:
                assert member in [f.name for f in field.kind.fields], \
                    f"{path.name}: frame.{name}[].{member}"
            used += 1
    assert used > 20


def test_every_enum_and_limit_the_glsl_uses_comes_from_glsl_defines():
    defined = dict(glsl_defines())
    assert len(defined) == len(glsl_defines()), "no name defined twice"
    used = set()
    for path in SHADERS:
        code = _glsl_code(path)
        assert not re.search(r"#\s*define\s+(DEBUG|PCF|SPLIT|MAX)_", code), \
            f"{path.name} defines an enum or limit by hand; add it to frame_layout instead"
        used |= set(re.findall(r"\b(?:DEBUG|PCF|SPLIT|MAX)_[A-Z0-9_]+\b", code))
    assert {"DEBUG_CASCADES", "PCF_GRID", "MAX_CASCADES"} <= used
    assert used <= set(defined), f"not defined: {sorted(used - set(defined))}"


def test_enum_values_are_their_positions():
    defined = dict(glsl_defines())
    for prefix, members in frame_layout.GLSL_ENUMS:
        for index, member in enumerate(members):
            assert defined[f"{prefix}_{member}"] == str(index)
    assert frame_layout.DEBUG_VIEW_INDEX["TEXEL_DENSITY"] == 4
    assert frame_layout.PCF_PATTERN_INDEX["NINE_TAP"] == 2


@pytest.mark.parametrize("name, setting", [("DEBUG_VIEWS", "debug_view"),
                                           ("PCF_PATTERNS", "pcf_pattern"),
                                           ("SPLIT_SCHEMES", "split_scheme")])
def test_enums_match_the_blender_settings(name, setting):
    assert settings_model.BY_IDENTIFIER[setting].identifiers == getattr(frame_layout, name)


def test_limits_and_schemes_agree_with_cascades():
    assert cascades.MAX_CASCADES == frame_layout.MAX_CASCADES
    assert cascades.SPLIT_SCHEMES == frame_layout.SPLIT_SCHEMES


# ---- pack_frame ---------------------------------------------------------------------------

def _snapshot_and_plan():
    rng = np.random.default_rng(3)
    camera = SimpleNamespace(clip_from_world=rng.normal(size=(4, 4)),
                             world_from_view=np.eye(4) + 0.1 * rng.normal(size=(4, 4)),
                             position=(1.0, 2.0, 3.0), forward=(0.0, 1.0, 0.0),
                             is_perspective=True, width=640, height=360)
    settings = settings_model.default_settings(fade_out=True, fade_fraction=0.25, pcf_radius=2, pcf_sharpen=2.5,
                               pcf_pattern="CROSS5", depth_bias=0.5, slope_bias=1.5,
                               normal_offset=0.75, debug_view="TEXEL_DENSITY",
                               debug_shadow_map=3, debug_inset=True,
                               cascade_selection="DEPTH", ambient_occlusion=False,
                               ao_distance=0.0, ao_strength=0.0)
    spot = SpotLight(position=np.array([4.0, 5.0, 6.0]), direction=np.array([0.0, 0.0, -1.0]),
                     color=np.array([7.0, 8.0, 9.0]), radius=20.0, spot_size=1.0,
                     spot_blend=0.2, casts_shadow=True, world_from_light=np.eye(4),
                     clip_start=0.1)
    snap = SimpleNamespace(
        camera=camera, settings=settings,
        sun=Sun(to_light=np.array([0.0, 0.6, 0.8]), color=np.array([2.0, 2.0, 2.0]),
                casts_shadow=True),
        points=[PointLight(np.array([1.0, 1.0, 1.0]), np.array([0.5, 0.25, 0.125]), 10.0)],
        spots=[spot, spot], ambient=np.array([0.1, 0.2, 0.3]), world_sh=None,
        background=np.array([0.4, 0.5, 0.6]), film_transparent=True, sample_index=0)
    tiles = [ShadowTile(rng.normal(size=(4, 4)), 1024 >> i, 0.01 * (i + 1), 1.0 + i, 50.0 + i,
                        False, origin=(1024 * i, 0), display_near=2.0 + i) for i in range(2)]
    tiles.append(ShadowTile(rng.normal(size=(4, 4)), 512, 0.002, 0.1, 20.0, True,
                            origin=(0, 1024), display_near=0.5))
    plan = ShadowPlan(tiles=tiles, cascade_count=2, splits=np.array([0.1, 10.0, 40.0]),
                      bands=np.array([1.0, 2.0, 0.0, 0.0]), shadow_distance=40.0,
                      spot_tiles={0: 2})
    return snap, plan


def test_pack_frame_fills_the_frame_block_by_name():
    snap, plan = _snapshot_and_plan()
    frame = FRAME_LAYOUT.unpack(pack_frame(snap, plan))
    assert frame["is_perspective"] == 1 and frame["viewport_size"].tolist() == [640, 360]
    assert frame["background_alpha"] == 0.0, "film transparent"
    # No environment: the World's harmonics are the uniform ambient colour's.
    np.testing.assert_allclose(frame["world_sh"][0][:3],
                               np.array([0.1, 0.2, 0.3]) * 4.0 * np.pi * 0.282095, rtol=1e-6)
    assert not np.any(frame["world_sh"][1:])
    assert frame["has_sun"] == 1 and frame["sun_casts_shadow"] == 1
    assert frame["cascade_count"] == 2 and frame["shadow_distance"] == 40.0
    assert frame["fade_start_depth"] == 30.0
    assert frame["pcf_radius_texels"] == 2.0 and frame["pcf_pattern"] == 1
    assert frame["pcf_sharpen"] == 2.5
    assert (frame["depth_bias_texels"], frame["slope_bias_texels"],
            frame["normal_offset_texels"]) == (0.5, 1.5, 0.75)
    assert frame["point_light_count"] == 1 and frame["spot_light_count"] == 2
    assert (frame["debug_view"], frame["debug_shadow_map"], frame["debug_inset"]) == (4, 3, 1)
    assert frame["cascade_selection"] == 1                      # DEPTH
    assert [c["far_depth"] for c in frame["cascades"]] == [10.0, 40.0, np.float32(1e30),
                                                           np.float32(1e30)]
    assert [c["near_depth"] for c in frame["cascades"]][:2] == [np.float32(0.1), 10.0]
    assert [c["blend_band"] for c in frame["cascades"]] == [1.0, 2.0, 0.0, 0.0]
    for tile, packed in zip(plan.tiles, frame["shadow_tiles"]):
        np.testing.assert_allclose(packed["shadow_from_world"],
                                   WINDOW_FROM_CLIP @ tile.clip_from_world, rtol=1e-6)
        assert packed["atlas_origin"].tolist() == list(tile.origin)
        assert packed["resolution"] == tile.resolution
        assert packed["is_perspective"] == int(tile.is_perspective)
        assert packed["light_far"] == tile.far
    assert frame["point_lights"][0]["radius"] == 10.0
    assert frame["point_lights"][0]["color"].tolist() == [0.5, 0.25, 0.125]
    assert [s["shadow_tile"] for s in frame["spot_lights"][:2]] == [2, -1]
    cos_outer, cos_inner = spot_cone_cosines(snap.spots[0])
    assert frame["spot_lights"][0]["cos_outer"] == np.float32(cos_outer)
    assert frame["spot_lights"][0]["cos_inner"] == np.float32(cos_inner)
