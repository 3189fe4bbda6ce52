"""The frame uniform block shared by Python and GLSL, and the limits and enums both use.

Owns ``FRAME_LAYOUT`` (generates the GLSL struct and packs the numpy data from one
table, so the two cannot disagree) and the constants the shaders see as ``#define``s.
numpy only.
"""

import numpy as np

# --------------------------------------------------------------------------------------
# Uniform blocks (std140; vec4 / mat4 fields only, so the layout is just 16-byte slots)
# --------------------------------------------------------------------------------------


class UniformLayout:
    """A std140 struct made of vec4 and mat4 fields (arrays allowed).

    ``fields`` is a sequence of ``(name, glsl_type, count)``. Only vec4/mat4 are allowed
    because their std140 size equals their natural size, which keeps packing trivial.
    """

    def __init__(self, type_name, fields):
        self.type_name = type_name
        self.offsets = {}
        offset = 0
        for name, glsl_type, count in fields:
            floats = {"vec4": 4, "mat4": 16}[glsl_type]
            self.offsets[name] = (offset, glsl_type, count, floats)
            offset += floats * count
        self.fields = tuple(fields)
        self.float_count = offset

    def glsl(self):
        lines = [f"struct {self.type_name} {{"]
        for name, glsl_type, count in self.fields:
            lines.append(f"  {glsl_type} {name}" + (f"[{count}];" if count > 1 else ";"))
        lines.append("};")
        return "\n".join(lines) + "\n"

    def new_data(self):
        return np.zeros(self.float_count, dtype=np.float32)

    def set(self, data, name, value, index=0):
        """Write ``value`` into field ``name`` (matrices are given row-major, numpy style)."""
        offset, glsl_type, count, floats = self.offsets[name]
        if not 0 <= index < count:
            raise IndexError(f"{self.type_name}.{name}[{index}] out of range ({count})")
        start = offset + index * floats
        value = np.asarray(value, dtype=np.float32)
        if glsl_type == "mat4":
            # NOTE: GLSL matrices are column-major; numpy's are row-major. Upload M.T.
            data[start:start + 16] = value.reshape(4, 4).T.ravel()
        else:
            flat = value.ravel()
            data[start:start + len(flat)] = flat


DEBUG_VIEW_INDEX = {"NONE": 0, "CASCADES": 1, "SHADOW_FACTOR": 2, "SHADOW_MAP": 3,
                    "TEXEL_DENSITY": 4, "ALBEDO": 5, "NORMAL": 6, "POSITION": 7,
                    "DEPTH": 8, "SPECULAR": 9}
PCF_PATTERN_INDEX = {"GRID": 0, "CROSS5": 1, "NINE_TAP": 2}
MAX_CASCADES = 4
MAX_POINT_LIGHTS = 64
MAX_SPOT_LIGHTS = 8
MAX_SHADOW_TILES = MAX_CASCADES + MAX_SPOT_LIGHTS

# Everything the lighting pass needs for one frame. Packed by pipeline.py.
FRAME_LAYOUT = UniformLayout("FrameData", (
    ("clip_from_world", "mat4", 1),
    ("view_from_world", "mat4", 1),
    ("world_from_clip", "mat4", 1),    # rebuilds world positions from G-buffer view depth
    ("camera_position", "vec4", 1),    # xyz, w = 1 perspective / 0 orthographic
    ("camera_forward", "vec4", 1),     # xyz world view direction
    ("viewport", "vec4", 1),           # width, height, 1/width, 1/height (pixels)
    ("ambient", "vec4", 1),            # rgb ambient, a = background alpha (0 film transparent)
    ("background", "vec4", 1),         # rgb world colour
    ("sun_direction", "vec4", 1),      # xyz towards the sun, w = 1 if there is a sun
    ("sun_color", "vec4", 1),          # rgb intensity, w = 1 if the sun casts shadows
    ("shadow_params", "vec4", 1),      # cascade count, shadow distance, fade start, blend band
    ("filter_params", "vec4", 1),      # pcf radius, pcf pattern, depth bias, slope bias (texels)
    ("bias_params", "vec4", 1),        # normal offset (texels), spot count, point count, 0
    ("debug_params", "vec4", 1),       # debug view, shadow map index, inset on, 0
    ("cascade_splits", "vec4", 1),     # far view depth of cascades 0..3
    ("cascade_near", "vec4", 1),       # near view depth of cascades 0..3 (selection)
    ("cascade_band", "vec4", 1),       # blend band width before the far split of 0..3
    ("shadow_from_world", "mat4", MAX_SHADOW_TILES),  # atlas-window (0..1) from world
    ("shadow_tiles", "vec4", MAX_SHADOW_TILES),       # uv offset xy, uv scale, texel size world
    ("shadow_depth", "vec4", MAX_SHADOW_TILES),       # light near, far, resolution, is_perspective
    ("point_lights", "vec4", 2 * MAX_POINT_LIGHTS),   # (position, radius), (color, 0)
    ("spot_lights", "vec4", 4 * MAX_SPOT_LIGHTS),     # (pos, radius), (color, shadow tile or -1),
                                                      # (direction, cos outer), (cos inner, ...)
))
