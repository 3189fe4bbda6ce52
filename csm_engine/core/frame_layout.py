"""The frame uniform block shared by Python and GLSL, and the limits and enums both use.

Owns ``UniformLayout`` (a std140 struct described once, as a table of named fields, which
generates both the GLSL struct text and the numpy packing, so the two cannot disagree),
``FRAME_LAYOUT`` (everything the G-buffer and lighting passes read for one frame), the
enums the shaders switch on (debug views, PCF patterns, split schemes), the array limits,
and ``glsl_defines()``, which hands all of those to every program as ``#define``s.
numpy only.
"""

import re
from types import MappingProxyType

import numpy as np

# --------------------------------------------------------------------------------------
# Limits and enums: defined here once, seen by GLSL through glsl_defines()
# --------------------------------------------------------------------------------------

MAX_CASCADES = 4
MAX_POINT_LIGHTS = 64
MAX_SPOT_LIGHTS = 8
MAX_POINT_SHADOWS = 4     # point lights with cube-map shadows (six tiles each)
# One tile per cascade and shadowed spot, six per shadowed point light.
MAX_SHADOW_TILES = MAX_CASCADES + MAX_SPOT_LIGHTS + 6 * MAX_POINT_SHADOWS

# Identifiers as the Blender settings spell them (EnumProperty items); the GLSL value of
# each is its position here, so only ever append.
DEBUG_VIEWS = ("NONE", "CASCADES", "SHADOW_FACTOR", "SHADOW_MAP", "TEXEL_DENSITY", "ALBEDO",
               "NORMAL", "POSITION", "DEPTH", "SPECULAR", "AMBIENT_OCCLUSION",
               "SHADOW_ERROR")
PCF_PATTERNS = ("GRID", "CROSS5", "NINE_TAP")
SPLIT_SCHEMES = ("UNIFORM", "LOG", "HYBRID", "MANUAL")
# How a point or spot light dims with distance (docs/lighting.md): PHYSICAL is EEVEE's
# inverse square (with its smooth cut-off at the influence radius); LINEAR_RADIUS is the
# course's 1 - d/radius.
LIGHT_FALLOFFS = ("PHYSICAL", "LINEAR_RADIUS")
# How shadow edges are filtered: one hard tap, the fixed PCF kernel (radius and pattern
# settings), soft shadows whose penumbra follows the light's size (PCSS), or the sun's
# exact hard shadow by shadow volumes.
SHADOW_FILTERS = ("HARD", "PCF", "SOFT", "EXACT")
# Which cascade a pixel reads: the finest whose shadow map holds it (as the DirectX SDK's
# Map Selection and MJP's Projection mode), or the one whose view-depth slice holds it
# (interval selection, the course's bands).
CASCADE_SELECTIONS = ("MAP", "DEPTH")


def enum_positions(members):
    """Each member's position in ``members`` (its GLSL value), read-only."""
    return MappingProxyType({name: index for index, name in enumerate(members)})


DEBUG_VIEW_INDEX = enum_positions(DEBUG_VIEWS)
PCF_PATTERN_INDEX = enum_positions(PCF_PATTERNS)
SPLIT_SCHEME_INDEX = enum_positions(SPLIT_SCHEMES)
LIGHT_FALLOFF_INDEX = enum_positions(LIGHT_FALLOFFS)
SHADOW_FILTER_INDEX = enum_positions(SHADOW_FILTERS)
CASCADE_SELECTION_INDEX = enum_positions(CASCADE_SELECTIONS)

# GLSL name prefix of each enum: DEBUG_VIEWS' "SHADOW_MAP" is DEBUG_SHADOW_MAP in GLSL.
GLSL_ENUMS = (("DEBUG", DEBUG_VIEWS), ("PCF", PCF_PATTERNS), ("SPLIT", SPLIT_SCHEMES),
              ("FALLOFF", LIGHT_FALLOFFS), ("FILTER", SHADOW_FILTERS),
              ("SELECT", CASCADE_SELECTIONS))


def glsl_defines():
    """Every ``(name, value)`` ``#define`` the programs get, values as GLSL text: the
    array limits and one constant per enum member (``DEBUG_CASCADES``, ``PCF_GRID``, ...)."""
    defines = [("MAX_CASCADES", MAX_CASCADES), ("MAX_POINT_LIGHTS", MAX_POINT_LIGHTS),
               ("MAX_SPOT_LIGHTS", MAX_SPOT_LIGHTS), ("MAX_SHADOW_TILES", MAX_SHADOW_TILES),
               ("MAX_POINT_SHADOWS", MAX_POINT_SHADOWS)]
    for prefix, members in GLSL_ENUMS:
        defines += [(f"{prefix}_{member}", index) for index, member in enumerate(members)]
    return [(name, str(value)) for name, value in defines]


# --------------------------------------------------------------------------------------
# std140 uniform structs
# --------------------------------------------------------------------------------------

# GLSL type: (components, base alignment in bytes, size in bytes, numpy dtype). std140
# (OpenGL 4.5 spec 7.6.2.2): a scalar aligns to 4, vec2 to 8, vec3 and vec4 to 16; a vec3
# is 12 bytes, so a scalar after it fills its 4th slot; a column-major mat4 is an array of
# 4 vec4 columns.
_BASIC = MappingProxyType({
    "float": (1, 4, 4, np.float32),
    "int": (1, 4, 4, np.int32),
    "vec2": (2, 8, 8, np.float32),
    "vec3": (3, 16, 12, np.float32),
    "vec4": (4, 16, 16, np.float32),
    "mat4": (16, 16, 64, np.float32),
})

# Words a field must not be named after: reserved in some GLSL version Blender targets.
_RESERVED = frozenset({"filter", "sample", "input", "output", "common", "partition",
                       "active", "resource", "patch", "buffer", "shared", "precise",
                       "layout"})


# Single values the packing writes directly (see UniformLayout._write_one).
_NUMBERS = (int, float, np.number)


def _round_up(value, multiple):
    return (value + multiple - 1) // multiple * multiple


class Field:
    """One member of a ``UniformLayout``: ``kind`` is a GLSL type name or another layout
    (a nested struct); ``count`` is the array length, None for a single value."""

    def __init__(self, name, kind, count, doc, offset, stride):
        self.name, self.kind, self.count, self.doc = name, kind, count, doc
        self.offset = offset      # bytes from the start of the enclosing struct
        self.stride = stride      # bytes from one array element to the next (std140)
        # One number (True: an int, False: a float), else None: written directly by write.
        self.single = None if isinstance(kind, UniformLayout) or _BASIC[kind][0] != 1 \
            else _BASIC[kind][3] is np.int32

    @property
    def is_struct(self):
        return isinstance(self.kind, UniformLayout)

    @property
    def glsl_type(self):
        return self.kind.type_name if self.is_struct else self.kind

    def __repr__(self):
        return (f"Field({self.name!r}, {self.glsl_type}, count={self.count}, "
                f"offset={self.offset}, stride={self.stride})")


class UniformLayout:
    """A std140 struct described by a table of named fields.

    ``fields`` is a sequence of ``(name, type, doc)`` or ``(name, type, count, doc)`` rows:
    ``type`` is ``float``, ``int``, ``vec2``, ``vec3``, ``vec4``, ``mat4`` or another
    ``UniformLayout`` (a struct), ``count`` makes an array, ``doc`` says what the value
    means and in which unit (it goes into the GLSL as a comment too).

    ``glsl()`` writes the struct (after the structs it uses); ``pack(values)`` builds the
    float32 buffer to upload from a dict of field values (matrices row-major, numpy style;
    array-of-struct fields as lists of dicts); ``unpack(data)`` reads one back.
    """

    def __init__(self, type_name, fields):
        if not re.fullmatch(r"[A-Za-z_]\w*", type_name):
            raise ValueError(f"struct name '{type_name}' is not a GLSL identifier")
        self.type_name = type_name
        self.fields = []
        self._by_name = {}
        offset = 0
        alignment = 4
        for row in fields:
            name, kind, count, doc = row if len(row) == 4 else (row[0], row[1], None, row[2])
            self._check(name, kind, count, doc)
            if isinstance(kind, UniformLayout):
                element_align, element_size = kind.alignment, kind.size
            else:
                _, element_align, element_size, _ = _BASIC[kind]
            if count is None:
                align, stride, size = element_align, element_size, element_size
            else:
                # NOTE: std140 rounds an array's alignment and element stride up to a vec4,
                # so float[4] takes 64 bytes, not 16.
                align = _round_up(element_align, 16)
                stride = _round_up(element_size, 16)
                size = stride * count
            offset = _round_up(offset, align)
            field = Field(name, kind, count, doc, offset, stride)
            self.fields.append(field)
            self._by_name[name] = field
            offset += size
            alignment = max(alignment, align)
        # A struct aligns to a vec4 and its size is padded to its alignment.
        self.alignment = _round_up(alignment, 16)
        self.size = _round_up(offset, self.alignment)

    def _check(self, name, kind, count, doc):
        where = f"{self.type_name}.{name}"
        if not isinstance(name, str) or not re.fullmatch(r"[a-z_][a-z0-9_]*", name):
            raise ValueError(f"{where}: field names are lower_case GLSL identifiers")
        if name in _RESERVED or name.startswith("gl_"):
            raise ValueError(f"{where}: '{name}' is reserved in GLSL")
        if name in self._by_name:
            raise ValueError(f"{where}: field named twice")
        if not isinstance(kind, UniformLayout) and kind not in _BASIC:
            raise ValueError(f"{where}: type '{kind}' is not one of {', '.join(_BASIC)} "
                             "or a UniformLayout")
        if count is not None and (not isinstance(count, int) or count < 1):
            raise ValueError(f"{where}: array length must be a positive int, got {count!r}")
        if not isinstance(doc, str) or not doc.strip() or "*/" in doc or "\n" in doc:
            raise ValueError(f"{where}: needs a one-line doc (meaning and unit), without '*/'")

    # ---- GLSL ------------------------------------------------------------------------

    def structs(self):
        """This struct and every struct it uses, each once, dependencies first."""
        order = []
        for field in self.fields:
            if field.is_struct:
                order += [s for s in field.kind.structs() if s not in order]
        return order + [self]

    def glsl(self):
        """GLSL text declaring this struct and the structs it uses."""
        return "\n".join(s._glsl_struct() for s in self.structs())

    def _glsl_struct(self):
        lines = [f"/* Generated from core/frame_layout.py (std140, {self.size} bytes): edit the "
                 "table there, not this text. */", f"struct {self.type_name} {{"]
        for field in self.fields:
            array = f"[{field.count}]" if field.count is not None else ""
            declaration = f"  {field.glsl_type} {field.name}{array};"
            lines.append(f"{declaration:<40} /* @{field.offset}: {field.doc} */")
        lines.append("};")
        return "\n".join(lines) + "\n"

    # ---- packing ---------------------------------------------------------------------

    def field(self, name):
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"{self.type_name} has no field '{name}'; fields: "
                           f"{', '.join(self._by_name)}") from None

    def field_bytes(self, data, names):
        """The bytes of some single (non-array, non-struct) fields of a packed ``data``:
        a cheap value to tell whether two packed blocks agree on those fields."""
        parts = []
        for name in names:
            field = self.field(name)
            size = _BASIC[field.kind][2]
            parts.append(data[field.offset // 4:(field.offset + size) // 4].tobytes())
        return b"".join(parts)

    def new_data(self):
        """A zeroed float32 buffer of this struct's std140 size (ints share its bytes)."""
        return np.zeros(self.size // 4, dtype=np.float32)

    def pack(self, values):
        """A new buffer holding ``values`` (field name -> value); missing fields are 0."""
        data = self.new_data()
        self.write(data, values)
        return data

    def write(self, data, values, base=0):
        """Write ``values`` into ``data`` with this struct starting at byte ``base``."""
        ints = None
        for name, value in values.items():
            field = self._by_name.get(name) or self.field(name)
            if field.count is None:
                single = field.single
                if single is not None and isinstance(value, _NUMBERS):
                    # NOTE: most of a frame block is single numbers; written here without
                    # the array round trip of _write_one (a viewport redraw packs a frame
                    # or two). Same checks, same float32 rounding.
                    number = float(value)
                    if single:
                        if number != round(number):
                            raise ValueError(f"{self.type_name}.{name}: int field given "
                                             f"{value!r}")
                        if ints is None:
                            ints = data.view(np.int32)
                        ints[(base + field.offset) // 4] = int(number)
                    else:
                        data[(base + field.offset) // 4] = number
                    continue
                self._write_one(data, field, base + field.offset, value)
                continue
            items = list(value)
            if len(items) > field.count:
                raise IndexError(f"{self.type_name}.{name}: {len(items)} values for "
                                 f"an array of {field.count}")
            for index, item in enumerate(items):
                self._write_one(data, field, base + field.offset + index * field.stride, item)

    def _write_one(self, data, field, at, value):
        if field.is_struct:
            if not isinstance(value, dict):
                raise TypeError(f"{self.type_name}.{field.name}: expected a dict of "
                                f"{field.kind.type_name} fields, got {type(value).__name__}")
            field.kind.write(data, value, at)
            return
        components, _, _, dtype = _BASIC[field.kind]
        if field.single is not None and isinstance(value, _NUMBERS):
            number = float(value)
            if field.single:
                if number != round(number):
                    raise ValueError(f"{self.type_name}.{field.name}: int field given "
                                     f"{value!r}")
                data.view(np.int32)[at // 4] = int(number)
            else:
                data[at // 4] = number
            return
        flat = np.asarray(value, dtype=np.float64)
        if field.kind == "mat4":
            if flat.shape != (4, 4):
                raise ValueError(f"{self.type_name}.{field.name}: expected a 4x4 matrix, "
                                 f"got shape {flat.shape}")
            # NOTE: GLSL matrices are column-major and numpy's row-major: upload M.T.
            flat = flat.T
        flat = flat.ravel()
        if flat.size != components:
            raise ValueError(f"{self.type_name}.{field.name}: expected {components} "
                             f"value(s) for a {field.kind}, got {flat.size}")
        if dtype is np.int32:
            if not np.all(flat == np.round(flat)):
                raise ValueError(f"{self.type_name}.{field.name}: int field given {value!r}")
            data.view(np.int32)[at // 4:at // 4 + components] = flat.astype(np.int32)
        else:
            data[at // 4:at // 4 + components] = flat

    def unpack(self, data, base=0):
        """Read every field back: field name -> float, int, numpy array (matrices
        row-major again) or, for a struct, a dict (a list of them for an array)."""
        out = {}
        for field in self.fields:
            if field.count is None:
                out[field.name] = self._read_one(data, field, base + field.offset)
            else:
                out[field.name] = [self._read_one(data, field, base + field.offset + i *
                                                  field.stride) for i in range(field.count)]
        return out

    def _read_one(self, data, field, at):
        if field.is_struct:
            return field.kind.unpack(data, at)
        components, _, _, dtype = _BASIC[field.kind]
        source = data.view(np.int32) if dtype is np.int32 else data
        values = source[at // 4:at // 4 + components].copy()
        if field.kind == "mat4":
            return values.reshape(4, 4).T
        return values[0].item() if components == 1 else values


# --------------------------------------------------------------------------------------
# The frame block. Must match every GLSL use of ``frame.*`` (the struct text is generated
# from this table; shaders.py adds it to each program that reads the frame).
# --------------------------------------------------------------------------------------

CASCADE_LAYOUT = UniformLayout("CascadeData", (
    ("near_depth", "float", "view depth where this cascade's slice begins (scene units)"),
    ("far_depth", "float", "view depth where it ends; 1e30 for cascades not in use"),
    ("blend_band", "float", "view-depth width before far_depth blended into the next one"),
))

SHADOW_TILE_LAYOUT = UniformLayout("ShadowTileData", (
    ("shadow_from_world", "mat4", "tile window coordinates (0..1 in x, y, depth) from world"),
    ("atlas_origin", "vec2", "lower-left corner of the tile in the atlas (texels)"),
    ("resolution", "float", "tile width and height (texels)"),
    ("texel_world", "float", "orthographic: scene units per texel; perspective: per unit "
                             "of distance from the light"),
    ("texel_world_xy", "vec2", "texel_world along the tile's x and y: a cascade fitted to "
                               "its visible receivers is rectangular (soft shadows size "
                               "their penumbrae in the world, per axis)"),
    ("light_near", "float", "light's near plane (scene units from the light)"),
    ("light_far", "float", "light's far plane (scene units from the light)"),
    ("is_perspective", "int", "1 perspective (spot) tile, 0 orthographic (sun cascade)"),
    ("display_near", "float", "where the scene begins in this light's depth (scene units; "
                              "the shadow-map debug view's black)"),
    ("window_normal_from_world", "mat4", "orthographic tiles: a world normal into window "
                                         "space (inverse transpose of shadow_from_world's "
                                         "3x3), giving a receiver plane's depth slope"),
))

# What point and spot lights both begin with (lights.glsl reads them alike).
_LOCAL_LIGHT_FIELDS = (
    ("position", "vec3", "world position (scene units)"),
    ("radius", "float", "distance where the light ends (scene units): influence radius or "
                        "the linear falloff's zero"),
    ("color", "vec3", "PHYSICAL: radiant intensity (W/sr); LINEAR_RADIUS: irradiance at "
                      "the light (W/m^2)"),
)

POINT_LIGHT_LAYOUT = UniformLayout("PointLightData", _LOCAL_LIGHT_FIELDS + (
    ("falloff", "int", "FALLOFF_* with distance"),
    ("source_radius", "float", "Blender's Radius (scene units): soft shadows' penumbra"),
))

SPOT_LIGHT_LAYOUT = UniformLayout("SpotLightData", _LOCAL_LIGHT_FIELDS + (
    ("shadow_tile", "int", "index into shadow_tiles, -1 when the spot casts no shadow"),
    ("direction", "vec3", "unit world direction the spot shines along"),
    ("cos_outer", "float", "cosine of the half cone angle: no light outside it"),
    ("cos_inner", "float", "cosine of the angle where the edge blend begins: full inside"),
    ("falloff", "int", "FALLOFF_* with distance"),
    ("source_radius", "float", "radius of the light's sphere (scene units, Blender's Radius): "
                               "the size of its soft shadows' penumbrae"),
))

# Everything the G-buffer and lighting passes read for one frame. Packed by
# frame_block.pack_frame.
FRAME_LAYOUT = UniformLayout("FrameData", (
    ("clip_from_world", "mat4", "camera clip space (OpenGL) from world"),
    ("view_from_world", "mat4", "camera view space from world"),
    ("world_from_clip", "mat4", "inverse of clip_from_world: rebuilds world positions"),
    ("camera_position", "vec3", "world position of the camera (scene units)"),
    ("is_perspective", "int", "1 perspective camera, 0 orthographic"),
    ("camera_forward", "vec3", "unit world direction the camera looks along"),
    ("viewport_size", "vec2", "width and height of the render (pixels)"),
    ("ambient_color", "vec3", "uniform World radiance lighting every surface (linear rgb, "
                              "W/m^2/sr)"),
    ("world_sh", "vec4", 9, "the World's radiance lighting every surface as spherical "
                            "harmonics up to band 2 (rgb, W/m^2/sr; core/world_light.py)"),
    ("background_alpha", "float", "alpha of background pixels: 0 with Film > Transparent"),
    ("background_color", "vec3", "linear rgb of the World behind the scene"),
    ("sun_direction", "vec3", "unit world direction towards the sun"),
    ("has_sun", "int", "1 if the scene has a sun, 0 otherwise"),
    ("sun_color", "vec3", "sun irradiance on a surface facing it (linear rgb, W/m^2)"),
    ("sun_casts_shadow", "int", "1 if the sun casts shadows (cascade_count > 0)"),
    ("cascade_count", "int", "cascades in use, 0..MAX_CASCADES"),
    ("cascade_selection", "int", "SELECT_* rule picking a pixel's cascade"),
    ("shadow_distance", "float", "view depth where sun shadows end (scene units)"),
    ("fade_start_depth", "float", "view depth where shadows begin to fade out (scene units)"),
    ("pcf_radius_texels", "float", "PCF kernel radius, a whole number of texels"),
    ("pcf_pattern", "int", "PCF_* tap pattern"),
    ("pcf_sharpen", "float", "PCF edge steepening around visibility 0.5 (1 = none)"),
    ("depth_bias_texels", "float", "constant depth bias (shadow texels)"),
    ("slope_bias_texels", "float", "depth bias per unit of tan(light angle) (texels)"),
    ("normal_offset_texels", "float", "lookup moved along the normal (shadow texels)"),
    ("sun_tan_half_angle", "float", "tan of half the sun's angular diameter (Blender's "
                                    "Angle): penumbra width per unit of blocker distance"),
    ("sample_index", "int", "which jittered sample of a final render this is (0 in the "
                            "viewport): moves per-pixel noise so samples average it away"),
    ("point_light_count", "int", "point_lights in use, 0..MAX_POINT_LIGHTS"),
    ("point_shadow_count", "int", "the first this many point_lights cast shadows, "
                                  "0..MAX_POINT_SHADOWS"),
    ("point_shadow_tiles", "int", "shadow_tiles index of the first one's +x face; point "
                                  "light i's face f is point_shadow_tiles + 6 i + f"),
    ("spot_light_count", "int", "spot_lights in use, 0..MAX_SPOT_LIGHTS"),
    ("debug_view", "int", "DEBUG_* view to draw, DEBUG_NONE for the lit image"),
    ("debug_shadow_map", "int", "shadow tile the shadow-map view shows (cascades first)"),
    ("debug_inset", "int", "1: show the shadow map as an inset over the lit image"),
    ("cascades", CASCADE_LAYOUT, MAX_CASCADES, "sun cascade slices, nearest first"),
    ("shadow_tiles", SHADOW_TILE_LAYOUT, MAX_SHADOW_TILES,
     "atlas tiles: one per cascade, then one per shadowed spot light"),
    ("point_lights", POINT_LIGHT_LAYOUT, MAX_POINT_LIGHTS, "point lights in use first"),
    ("spot_lights", SPOT_LIGHT_LAYOUT, MAX_SPOT_LIGHTS, "spot lights in use first"),
    # Screen-space ambient occlusion (ao_frag.glsl); packed by frame_block.pack_frame.
    ("ao_enabled", "int", "1: the ambient term is multiplied by the AO texture"),
    ("ao_distance", "float", "AO distance: farther surfaces do not occlude (scene units)"),
    ("ao_strength", "float", "AO blend, 0 (no effect) to 1 (the full occlusion)"),
    ("ao_pixels_per_unit", "float", "pixels one scene unit spans at view depth 1 "
                                    "(perspective) or anywhere (orthographic)"),
    ("ao_view_ray", "vec4", "view-space xy of a pixel = ndc * xy + zw, times the view "
                            "depth for a perspective camera"),
))
