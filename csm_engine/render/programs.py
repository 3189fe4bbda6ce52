"""The program table: every GLSL program the pipeline draws with, and its twins.

Owns ``PROGRAMS`` (program name -> its two stage files, vertex inputs, interface, push
constants, samplers, uniform blocks, fragment outputs and defines) and ``PASS_OUTPUTS``.
llvmpipe pays for code a pixel skips, so a feature a frame may not use (alpha masks,
normal maps, instancing, point and spot lights, debug views, render passes, emission...)
is a twin of its program compiled with a define, and the passes pick the twin their frame
needs; twins a render may never use are compiled when first drawn (``on_demand``).
``shaders.py`` compiles what this table describes. Pure data: no ``gpu`` here.
"""

# A full-screen triangle's vertex stage (fullscreen_vert.glsl), shared by the screen passes,
# and what most of them have: no push constants, no frame block, one colour output.
_FULLSCREEN = dict(vertex="fullscreen_vert.glsl", inputs=(("pos", "VEC2"),),
                   interface=(("screen_uv", "VEC2", "smooth"),), push=(), frame=False,
                   outputs=(("VEC4", "out_color"),))

# Each program: vertex inputs, interface (name, type, interpolation), push constants,
# samplers, whether it reads the frame uniform block, fragment outputs.
PROGRAMS = {
    "gbuffer": dict(
        vertex="gbuffer_vert.glsl", fragment="gbuffer_frag.glsl",
        inputs=(("pos", "VEC3"), ("nor", "VEC3"), ("uv", "VEC2")),
        interface=(("world_normal", "VEC3", "smooth"), ("tex_coord", "VEC2", "smooth"),
                   ("view_depth", "FLOAT", "smooth"), ("mirror_sign", "FLOAT", "flat"),
                   ("world_position", "VEC3", "smooth")),
        push=(("MAT4", "world_from_object"), ("FLOAT", "terminator_offset")),
        samplers=(("FLOAT_2D", "base_color_texture"), ("FLOAT_2D", "normal_texture"),
                  ("FLOAT_2D", "emission_texture"), ("FLOAT_2D", "surface_texture")),
        frame=True,
        material=True,      # MaterialData (core/material_layout.py) as "material"
        # The packed targets (gbuffer_layout.glsl), then those only some frames have.
        outputs=(("VEC4", "out_surface"), ("VEC2", "out_depth"), ("VEC4", "out_emission"),
                 ("VEC4", "out_coat")),
    ),
    "shadow": dict(
        vertex="shadow_vert.glsl", fragment="shadow_frag.glsl",
        inputs=(("pos", "VEC3"), ("uv", "VEC2")),
        interface=(("tex_coord", "VEC2", "smooth"),),
        push=(("MAT4", "clip_from_object"),),
        samplers=(("FLOAT_2D", "base_color_texture"),),
        frame=False,
        outputs=(("VEC4", "out_partial_caster"),),
    ),
    "lighting": dict(
        _FULLSCREEN, fragment="lighting_frag.glsl",
        samplers=(("FLOAT_2D", "gbuffer_surface_target"), ("FLOAT_2D", "gbuffer_depth"),
                  ("FLOAT_2D", "shadow_atlas"), ("FLOAT_2D", "shadow_partial"),
                  ("FLOAT_2D", "gbuffer_emission")),
        frame=True, outputs=(("VEC4", "out_color"), ("VEC4", "out_aux")),
    ),
    "background": dict(
        _FULLSCREEN, fragment="background_frag.glsl", samplers=(),
        frame=True, outputs=(("VEC4", "out_color"), ("VEC4", "out_aux")),
    ),
    "fxaa": dict(_FULLSCREEN, fragment="fxaa_frag.glsl", samplers=(("FLOAT_2D", "source"),)),
    "depth_range": dict(_FULLSCREEN, fragment="depth_range_frag.glsl",
                        samplers=(("FLOAT_2D", "source"),)),
    "accumulate": dict(
        _FULLSCREEN, fragment="accumulate_frag.glsl", push=(("FLOAT", "sample_share"),),
        samplers=(("FLOAT_2D", "previous"), ("FLOAT_2D", "current")),
    ),
    "lines": dict(
        vertex="lines_vert.glsl", fragment="lines_frag.glsl",
        inputs=(("pos", "VEC3"), ("color", "VEC4")),
        interface=(("line_color", "VEC4", "smooth"),),
        push=(("MAT4", "clip_from_world"),),
        samplers=(),
        frame=False,
        outputs=(("VEC4", "out_color"),),
    ),
}

# The visible depth range's first step, over the G-buffer's view depth.
PROGRAMS["depth_range_view"] = dict(PROGRAMS["depth_range"], defines=(("VIEW_DEPTH", "1"),))
# A final render's FXAA in three passes (fxaa_frag.glsl, render/antialiasing.py): a copy
# with the lumas; the edge mark (depth only); the edge walk where the mark's depth passes.
PROGRAMS["fxaa_luma"] = dict(PROGRAMS["fxaa"], defines=(("FXAA_LUMA", "1"),),
                             outputs=(("VEC4", "out_color"), ("FLOAT", "out_luma")))
PROGRAMS["fxaa_mark"] = dict(PROGRAMS["fxaa"], defines=(("FXAA_MARK", "1"),),
                             samplers=(("FLOAT_2D", "luma"),), outputs=())
PROGRAMS["fxaa_blend"] = dict(PROGRAMS["fxaa"], defines=(("FXAA_BLEND", "1"),),
                              samplers=(("FLOAT_2D", "source"), ("FLOAT_2D", "luma")))

# The G-buffer's normals unpacked for a read-back (the Normal pass).
PROGRAMS["gbuffer_normals"] = dict(
    PROGRAMS["depth_range"], fragment="gbuffer_normals_frag.glsl", on_demand=True,
    samplers=(("FLOAT_2D", "gbuffer_surface_target"), ("FLOAT_2D", "gbuffer_depth")),
    outputs=(("VEC4", "out_normal"),))

# NOTE: a fragment shader that may ``discard`` turns off the rasterizer's early depth test,
# so every hidden fragment runs the whole shader (llvmpipe: about half the G-buffer cost).
# Opaque materials therefore draw with programs that cannot discard; alpha-masked
# (cut-out) materials use these variants, compiled from the same files with ALPHA_MASK.
for _name in ("gbuffer", "shadow"):
    PROGRAMS[_name + "_masked"] = dict(PROGRAMS[_name], defines=(("ALPHA_MASK", "1"),),
                                       material=True)
# The partial-caster mask of the shadow atlas (shadow_frag.glsl, PARTIAL_CASTER): alpha-hashed
# casters drawn once more, without discarding, into the mask.
PROGRAMS["shadow_partial"] = dict(PROGRAMS["shadow"], defines=(("PARTIAL_CASTER", "1"),),
                                  samplers=())
# Materials without images: no texture reads at all (llvmpipe pays for a sample behind an
# `if` that skips it), so no samplers to bind either.
PROGRAMS["gbuffer_untextured"] = dict(PROGRAMS["gbuffer"], defines=(("UNTEXTURED", "1"),),
                                      samplers=())
# Meshes whose materials use a normal map carry a per-corner tangent (xyz, bitangent sign);
# only they pay for it, with these variants (NORMAL_MAP) of the G-buffer programs.
for _name in ("gbuffer", "gbuffer_masked"):
    _spec = PROGRAMS[_name]
    PROGRAMS[_name + "_tangent"] = dict(
        _spec, inputs=_spec["inputs"] + (("tan", "VEC4"),),
        interface=_spec["interface"] + (("world_tangent", "VEC4", "smooth"),),
        defines=_spec.get("defines", ()) + (("NORMAL_MAP", "1"),))

# Instanced twins of the mesh programs (INSTANCED, instance_matrix.glsl): every copy of a
# mesh in one draw, each reading its matrix from the texture instance_matrices
# (render/instancing.py) instead of the push constant.
_PER_DRAW_MATRICES = ("world_from_object", "clip_from_object")
for _name in [name for name in PROGRAMS if name.startswith(("gbuffer", "shadow"))]:
    _spec = PROGRAMS[_name]
    PROGRAMS[_name + "_instanced"] = dict(
        _spec, push=tuple(p for p in _spec["push"] if p[1] not in _PER_DRAW_MATRICES)
        + (("INT", "instance_offset"),),
        samplers=_spec["samplers"] + (("FLOAT_2D", "instance_matrices"),),
        defines=_spec.get("defines", ()) + (("INSTANCED", "1"),))

# Final renders with Cryptomatte passes draw the G-buffer a second time with these twins
# (CRYPTOMATTE): the sixth target, the coat's in the first draw, holds each pixel's object,
# material and asset IDs, set per draw (so such a G-buffer draws each copy on its own:
# there are no instanced twins of these).
for _name in [name for name in PROGRAMS
              if name.startswith("gbuffer") and not name.endswith("_instanced")]:
    _spec = PROGRAMS[_name]
    PROGRAMS[_name + "_ids"] = dict(
        _spec, on_demand=True,
        push=_spec["push"] + (("FLOAT", "cryptomatte_object"),
                                     ("FLOAT", "cryptomatte_material"),
                                     ("FLOAT", "cryptomatte_asset")),
        outputs=tuple(o for o in _spec["outputs"] if o[1] != "out_coat") +
        (("VEC4", "out_ids"),),
        defines=_spec.get("defines", ()) + (("CRYPTOMATTE", "1"),))

# Screen-space ambient occlusion (ao_frag.glsl), all at half resolution: the mask (depth
# only: where to search), the horizon search (visible and open arcs, view depth, packed
# normal) and the separable depth-aware blur, rows (the same sums) then columns (AO, view
# depth); lighting brings it to full resolution and multiplies its ambient term by it.
_AO_COMMON = dict(_FULLSCREEN, fragment="ao_frag.glsl", frame=True)
PROGRAMS["ao_mask"] = dict(_AO_COMMON, samplers=(("FLOAT_2D", "gbuffer_depth"),),
                           outputs=(), depth_write="ANY", defines=(("AO_MASK", "1"),))
PROGRAMS["ao"] = dict(_AO_COMMON, samplers=(("FLOAT_2D", "gbuffer_depth"),
                                            ("FLOAT_2D", "gbuffer_surface_target")),
                      outputs=(("VEC4", "out_ao_sums"),))
PROGRAMS["ao_blur_rows"] = dict(_AO_COMMON, samplers=(("FLOAT_2D", "ao_half"),),
                                outputs=(("VEC4", "out_ao_sums"),),
                                defines=(("AO_BLUR", "1"), ("AO_BLUR_AXIS", "0")))
PROGRAMS["ao_blur"] = dict(PROGRAMS["ao_blur_rows"], outputs=(("VEC2", "out_ao_depth"),),
                           defines=(("AO_BLUR", "1"), ("AO_BLUR_AXIS", "1")))
PROGRAMS["lighting"]["samplers"] += (("FLOAT_2D", "ambient_occlusion"),
                                     ("FLOAT_2D", "shadow_nearest_blocks"),
                                     ("FLOAT_2D", "shadow_volume_count"),
                                     ("FLOAT_2D", "bsdf_lut"), ("FLOAT_2D", "gbuffer_coat"))
# The Exact filter's shadow volumes counted per pixel (render/shadow_volumes.py).
PROGRAMS["shadow_volume"] = dict(
    vertex="shadow_volume_vert.glsl", fragment="shadow_volume_frag.glsl",
    inputs=(("pos", "VEC3"),), interface=(("volume_depth", "FLOAT", "smooth"),),
    push=(("VEC4", "channel"),),
    samplers=(("FLOAT_2D", "gbuffer_depth"),), frame=True,
    outputs=(("VEC4", "out_count"),))

def _add_lighting_twins(suffixes, defines=(), needs="", on_demand=True):
    """For every lighting program so far (whose name holds ``needs``) a twin named with
    each suffix, compiled with the defines added: ``suffixes`` is one suffix (with
    ``defines``) or a dict suffix -> its defines. ``on_demand``: compiled when first drawn
    (False keeps the program's own setting)."""
    if isinstance(suffixes, str):
        suffixes = {suffixes: defines}
    for name in [name for name in PROGRAMS if name.startswith("lighting") and needs in name]:
        spec = PROGRAMS[name]
        for suffix, added in suffixes.items():
            twin = dict(spec, defines=spec.get("defines", ()) + tuple(added))
            if on_demand:
                twin["on_demand"] = True
            PROGRAMS[name + suffix] = twin


# One lighting program per Shadow Filter setting (SHADOW_FILTER, see shadow_lookup.glsl): the
# plain "lighting" is PCF. Each has "_points" and "_spots" twins with the point- and
# spot-light loops (POINT_LIGHTS, SPOT_LIGHTS), used when the scene has such lights:
# llvmpipe pays for a loop's first pass even when it runs no times.
for _filter in ("HARD", "SOFT", "EXACT"):
    PROGRAMS["lighting_" + _filter.lower()] = dict(
        PROGRAMS["lighting"], defines=(("SHADOW_FILTER", f"FILTER_{_filter}"),))
# And each of those a "_debug" twin with the debug views (WITH_DEBUG_VIEWS), for the same
# reason: the lit image does not pay for the views' code.
# The point-light programs have a "_point_shadows" twin too, with the shadowed point
# lights' loop (POINT_SHADOWS).
for _feature, _define, _needs in (("_points", "POINT_LIGHTS", ""),
                                  ("_point_shadows", "POINT_SHADOWS", "_points"),
                                  ("_spots", "SPOT_LIGHTS", "")):
    _add_lighting_twins(_feature, ((_define, "1"),), needs=_needs, on_demand=False)
# Frames whose materials emit or are metal read the emission and metallic target with the
# "_emission" twins (SURFACE_EMISSION), frames with a coated material the coat target too
# with the "_coat" twins (SURFACE_EMISSION and SURFACE_COAT, as the G-buffer writes the
# emission target whenever it writes the coat's): the plain programs read neither, and
# without the metal and coat layers set up the lit image costs about a fifth less.
# Compiled when first drawn (``on_demand``, below).
_add_lighting_twins({"_emission": (("SURFACE_EMISSION", "1"),),
                     "_coat": (("SURFACE_EMISSION", "1"), ("SURFACE_COAT", "1"))})
# Frames whose World is an environment (spherical harmonics beyond band 0) draw with the
# "_environment" twins (WORLD_ENVIRONMENT, world_light.glsl); a one-colour World's light
# is the same whatever the direction, and the plain programs take it as such. Compiled
# when first drawn.
_add_lighting_twins("_environment", (("WORLD_ENVIRONMENT", "1"),))
# Frames with alpha-hashed shadow casters read the atlas's partial-caster mask with the
# "_hashed" twins (PARTIAL_CASTERS, shadow_atlas.glsl); elsewhere the mask is clear and
# PCF's lookup skips the fetch. Compiled when first drawn.
_add_lighting_twins("_hashed", (("PARTIAL_CASTERS", "1"),))
# PCF with the cross or nine-tap pattern, or Radius 0 (one hard tap), draws with the
# "_patterns" twins (WITH_PCF_PATTERNS, shadow_pcf.glsl); the plain PCF programs hold the
# grid alone. Compiled when first drawn.
_add_lighting_twins("_patterns", (("WITH_PCF_PATTERNS", "1"),))
_add_lighting_twins("_debug", (("WITH_DEBUG_VIEWS", "1"),), on_demand=False)

# Final renders with render passes on draw with PASSES twins of the lighting and background
# programs: four more targets (render/passes.py, LIGHTING_PASS_TARGETS) with the light and
# colour passes, so a render without them pays for none of it. These twins and the
# G-buffer's CRYPTOMATTE ones are compiled when first drawn (``on_demand``), not with the
# library: they would double its compile time (about 1 s here) for renders that never use
# them.
PASS_OUTPUTS = (("VEC4", "out_diffuse_light"), ("VEC4", "out_specular_light"),
                ("VEC4", "out_diffuse_color"), ("VEC4", "out_specular_color"))
for _name in [name for name in PROGRAMS if name.startswith(("lighting", "background"))]:
    _spec = PROGRAMS[_name]
    PROGRAMS[_name + "_passes"] = dict(
        _spec, on_demand=True, outputs=_spec["outputs"] + PASS_OUTPUTS,
        defines=_spec.get("defines", ()) + (("PASSES", "1"),))
