"""The per-material uniform block shared by Python and GLSL, and its enums.

Owns ``MATERIAL_LAYOUT`` (everything the G-buffer and shadow passes read of one material
slot: factors, which textures are bound, which texture channel holds what, the alpha and
normal-map settings), the alpha modes and metallic-roughness conventions the shaders switch
on, and ``pack_material``, which turns a plain dict of material values into the std140 data.
One ``GPUUniformBuf`` per material replaces per-draw push constants: those stop at 128
bytes (see /work/shared/docs/blender-gpu-notes.md). numpy only.
"""

from .frame_layout import UniformLayout, enum_positions

# How a surface's alpha is drawn (GLSL: ALPHA_OPAQUE, ...). OPAQUE ignores alpha and runs
# the programs that cannot discard; CLIP cuts out below the cutoff (glTF masks, Sponza);
# HASHED keeps a pixel when its alpha beats a stable per-pixel hash, so 50% alpha covers
# half the pixels of the image and half the texels of a shadow map.
ALPHA_MODES = ("OPAQUE", "CLIP", "HASHED")
ALPHA_MODE_INDEX = enum_positions(ALPHA_MODES)

# What the channels of the "metallic-roughness" texture mean (GLSL: SURFACE_*).
# PRINCIPLED: channels wired into Roughness / Metallic (Blender's glTF importer: G -> Roughness,
# B -> Metallic). COURSE: the course's glTF files, specular in blue and shininess in green
# (docs/materials.md).
SURFACE_CONVENTIONS = ("PRINCIPLED", "COURSE")
SURFACE_CONVENTION_INDEX = enum_positions(SURFACE_CONVENTIONS)

GLSL_ENUMS = (("ALPHA", ALPHA_MODES), ("SURFACE", SURFACE_CONVENTIONS))

# Must match every GLSL use of ``material.*`` (the struct text is generated from this
# table; shaders.py adds it to the G-buffer and shadow programs).
MATERIAL_LAYOUT = UniformLayout("MaterialData", (
    ("base_color", "vec4", "linear rgb and alpha factors; multiply the base-colour texture"),
    ("emission", "vec3", "emitted radiance, Emission Color x Strength (linear rgb, W/m^2/sr "
                         "as EEVEE); multiplies the emission texture"),
    ("metallic", "float", "0 dielectric .. 1 metal (Principled Metallic)"),
    ("roughness", "float", "0 mirror .. 1 fully rough (Principled Roughness)"),
    ("specular_level", "float", "Principled Specular (IOR Level): 0.5 is 4% reflectance"),
    ("coat_weight", "float", "Principled Coat Weight: 0 none .. 1 a full clear coat"),
    ("coat_roughness", "float", "Principled Coat Roughness"),
    ("coat_ior", "float", "Principled Coat IOR"),
    ("ior", "float", "Principled IOR of the specular layer (1.5 where Principled v1 has "
                     "none: Specular 0.5 is then 4% reflectance)"),
    ("normal_strength", "float", "Normal Map node Strength: 0 geometry normal .. 1 full map"),
    ("alpha_cutoff", "float", "ALPHA_CLIP: alpha below this is cut out (0..1)"),
    ("alpha_mode", "int", "ALPHA_* of the camera passes"),
    ("shadow_alpha_mode", "int", "ALPHA_* of the shadow pass"),
    ("has_base_texture", "int", "1: base_color_texture multiplies base_color"),
    ("has_normal_texture", "int", "1: normal_texture is a tangent-space normal map"),
    ("has_emission_texture", "int", "1: emission_texture multiplies emission"),
    ("surface_convention", "int", "SURFACE_* meaning of surface_texture's channels"),
    ("roughness_channel", "int", "PRINCIPLED: surface_texture channel (0..2) read as "
                                 "roughness, -1 none; COURSE: shininess / 256 (green)"),
    ("metallic_channel", "int", "PRINCIPLED: surface_texture channel read as metallic, -1 "
                                "none; COURSE: specular level (blue)"),
))


def glsl_defines():
    """The ``#define``s of the material enums: ALPHA_OPAQUE, ..., SURFACE_COURSE."""
    return [(f"{prefix}_{member}", str(index)) for prefix, members in GLSL_ENUMS
            for index, member in enumerate(members)]


def pack_material(values):
    """A material's std140 block (float32 array) from ``values`` (field name -> value);
    enum fields may be given by name ("HASHED", "COURSE")."""
    values = dict(values)
    for name in ("alpha_mode", "shadow_alpha_mode"):
        if isinstance(values.get(name), str):
            values[name] = ALPHA_MODE_INDEX[values[name]]
    if isinstance(values.get("surface_convention"), str):
        values["surface_convention"] = SURFACE_CONVENTION_INDEX[values["surface_convention"]]
    return MATERIAL_LAYOUT.pack(values)
