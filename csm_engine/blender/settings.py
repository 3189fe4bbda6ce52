"""The CSM render settings stored on each scene (``Scene.csm``).

Owns the ``CSMSettings`` PropertyGroup: every user-facing knob of the engine, saved with the
.blend file and animatable like any Blender property. Defaults are chosen against peers
(see ``docs/architecture.md``, ``../shared/docs/peers.md``) and the course's assignment:
3 cascades of 2048/1024/512, hybrid splits, 3x3 PCF, a blend band between cascades.
Lambda and the biases were chosen with the ground-truth tool (docs/ground-truth.md): with
lambda 0.75 the 2048 map covered only empty foreground in the course's camera, and a slope
bias of 1 texel became several scene units in the 512 cascade (missed contact shadows).

Nothing here touches the GPU. ``snapshot.py`` copies these values into plain data once per
frame, so the pipeline never reads ``bpy`` properties while drawing.
"""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty)

from ..core import frame_layout

SPLIT_SCHEMES_LABELS = {
    'UNIFORM': ("Uniform", "Equal slices of view depth: sharp far away, blurry near the camera"),
    'LOG': ("Logarithmic", "Slices grow geometrically with depth: even texel density on screen, "
                           "but the first slice is very thin"),
    'HYBRID': ("Hybrid", "Blend of logarithmic and uniform by Lambda "
                         "(z_i = L*n*(f/n)^(i/N) + (1-L)*(n + i/N*(f-n)))"),
    'MANUAL': ("Manual", "Split positions typed in as fractions of the shadow distance"),
}

CASCADE_SELECTIONS_LABELS = {
    'MAP': ("Shadow Map", "Each pixel reads the finest cascade whose shadow map holds it, "
                          "wherever its depth slice ends: a fitted cascade's map also covers "
                          "receivers beyond its split, so more of the view gets the sharpest "
                          "map (DirectX's Map Selection)"),
    'DEPTH': ("View Depth", "Each pixel reads the cascade whose slice of view depth holds it: "
                            "the cascades show as bands at the splits (interval selection)"),
}

PCF_PATTERNS_LABELS = {
    'GRID': ("Grid", "Square kernel of (2r+1)x(2r+1) taps; radius 0 is a single tap"),
    'CROSS5': ("5-tap cross", "Centre and 4 neighbours one texel away, scaled by the radius"),
    'NINE_TAP': ("9-tap", "Centre, 4 edges and 4 corners, scaled by the radius"),
}

DEBUG_VIEWS_LABELS = {
    'NONE': ("Lit", "The normal lit image"),
    'CASCADES': ("Cascade colours", "Tint by cascade: red nearest, green, blue, yellow farthest"),
    'SHADOW_FACTOR': ("Shadow factor", "Sun visibility only: white lit, black shadowed"),
    'SHADOW_MAP': ("Shadow map", "Linearized depth of one shadow map"),
    'TEXEL_DENSITY': ("Texel density", "Shadow-map texels per screen pixel as a heat map: "
                                       "blue = wasted resolution, red = too few texels"),
    'ALBEDO': ("G-buffer: albedo", "Base colour channel of the G-buffer"),
    'NORMAL': ("G-buffer: normal", "World-space normals mapped to 0..1"),
    'POSITION': ("G-buffer: position", "World position in repeating bands 1/20 of the shadow distance wide"),
    'DEPTH': ("G-buffer: depth", "View depth, normalised to the shadow distance"),
    'SPECULAR': ("G-buffer: specular", "Specular strength (red) and shininess / 256 (green)"),
    'AMBIENT_OCCLUSION': ("Ambient occlusion", "The factor the ambient light is multiplied by: "
                                               "white open, black fully occluded"),
}

LIGHT_FALLOFFS_LABELS = {
    'PHYSICAL': ("Physical", "Inverse square, as in EEVEE and Cycles: a point or spot light's "
                             "Power in watts, cut off smoothly at Custom Distance or where it "
                             "falls below EEVEE's Light Threshold"),
    'LINEAR_RADIUS': ("Linear to radius", "The course's falloff: full strength at the light, "
                                          "linearly to zero at its radius (Custom Distance); "
                                          "100 W shines with exactly the light's colour"),
}


SHADOW_FILTERS_LABELS = {
    "HARD": ("Hard", "One shadow-map tap per pixel: texel-sized stair steps on edges"),
    "PCF": ("PCF", "Percentage-closer filtering with the fixed kernel below (PCF Radius, "
                   "PCF Pattern): the same softness everywhere"),
    "SOFT": ("Soft (light size)", "Penumbrae from the light's real size (sun Angle, spot "
                                  "Radius): sharp at contact, wider with distance, as in "
                                  "Cycles (PCSS: blocker search, then a variable filter)"),
}


def _enum_items(identifiers, labels):
    """EnumProperty items in core's order (core owns the identifiers, and the GLSL values
    are their positions); here only their labels and tooltips."""
    if set(identifiers) != set(labels):
        raise RuntimeError(f"settings labels {sorted(labels)} do not match {identifiers}")
    return tuple((identifier, *labels[identifier]) for identifier in identifiers)


SPLIT_SCHEMES = _enum_items(frame_layout.SPLIT_SCHEMES, SPLIT_SCHEMES_LABELS)
PCF_PATTERNS = _enum_items(frame_layout.PCF_PATTERNS, PCF_PATTERNS_LABELS)
DEBUG_VIEWS = _enum_items(frame_layout.DEBUG_VIEWS, DEBUG_VIEWS_LABELS)
SHADOW_FILTERS = _enum_items(frame_layout.SHADOW_FILTERS, SHADOW_FILTERS_LABELS)
CASCADE_SELECTIONS = _enum_items(frame_layout.CASCADE_SELECTIONS, CASCADE_SELECTIONS_LABELS)
# 'PER_LIGHT' is not a falloff of its own: snapshot.py picks one of the others per light.
LIGHT_FALLOFFS = (('PER_LIGHT', "Per light", "Lights imported from a course scene file (they "
                   "carry the custom property csm_radius) fall off linearly to their radius; "
                   "every other light is physical, as in EEVEE"),) + \
    _enum_items(frame_layout.LIGHT_FALLOFFS, LIGHT_FALLOFFS_LABELS)

# Spelled out so the CLI's --set can report the valid choices.
ENUM_ITEMS = {
    "split_scheme": SPLIT_SCHEMES,
    "pcf_pattern": PCF_PATTERNS,
    "debug_view": DEBUG_VIEWS,
    "light_falloff": LIGHT_FALLOFFS,
    "shadow_filter": SHADOW_FILTERS,
    "cascade_selection": CASCADE_SELECTIONS,
}


def tag_3d_views_for_redraw(context):
    """Ask every 3D View to draw again (viewports do not notice PropertyGroup edits, shader
    reloads or sun edits by themselves)."""
    window_manager = getattr(context, "window_manager", None) if context else None
    for window in (window_manager.windows if window_manager is not None else ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def _redraw(self, context):
    tag_3d_views_for_redraw(context)


class CSMSettings(bpy.types.PropertyGroup):
    # --- Cascades -----------------------------------------------------------------------
    cascade_count: IntProperty(
        name="Cascades", default=3, min=1, max=4, update=_redraw,
        description="Number of shadow-map cascades covering the view depth (1 to 4). More: "
                    "sharper shadows near the camera, one more shadow pass each")
    split_scheme: EnumProperty(
        name="Split Scheme", items=SPLIT_SCHEMES, default='HYBRID', update=_redraw,
        description="How the shadow distance is divided between cascades. Logarithmic "
                    "gives the near cascades short ranges (sharp close up), uniform equal "
                    "ranges (sharper far away)")
    split_lambda: FloatProperty(
        name="Lambda", default=0.5, min=0.0, max=1.0, update=_redraw,
        description="Hybrid split weight over clip start .. shadow distance (Fit to Visible "
                    "Depth off), 0 to 1: 0 = uniform, 1 = logarithmic. Higher moves the "
                    "splits toward the camera: sharper near shadows, softer far ones")
    fitted_split_lambda: FloatProperty(
        name="Lambda (Fitted)", default=0.9, min=0.0, max=1.0, update=_redraw,
        description="Hybrid split weight over the depth the camera sees (Fit to Visible "
                    "Depth on), 0 to 1: 0 = uniform, 1 = logarithmic. That range starts at "
                    "the nearest visible surface, not at the clip start, so the logarithmic "
                    "split no longer spends the first cascade on empty foreground, and a "
                    "weight near 1 (sample-distribution shadow maps' logarithmic split) "
                    "gives the sharpest near shadows")
    manual_splits: FloatVectorProperty(
        name="Manual Splits", size=3, default=(0.1, 0.3, 0.6), min=0.0, max=1.0,
        update=_redraw,
        description="Far end of cascades 1..3 as fractions of the shadow distance "
                    "(must increase; only the first Cascades-1 are used)")
    shadow_distance: FloatProperty(
        name="Shadow Distance", default=0.0, min=0.0, soft_max=10000.0, unit='LENGTH',
        update=_redraw,
        description="View depth (scene units) up to which the sun casts shadows. "
                    "0 uses the camera's far clip")
    fit_to_visible: BoolProperty(
        name="Fit to Visible Depth", default=True, update=_redraw,
        description="Sample-distribution shadow maps: the splits divide the nearest to "
                    "farthest depth the camera actually sees (measured on the GPU each frame) "
                    "instead of clip start to shadow distance, so no cascade is spent on "
                    "empty depth. Sharper shadows wherever the view starts far away")
    cascade_selection: EnumProperty(
        name="Cascade Selection", items=CASCADE_SELECTIONS, default='MAP', update=_redraw,
        description="How a pixel picks its cascade: the finest shadow map that holds it, or "
                    "the slice of view depth it lies in")
    resolution: IntProperty(
        name="Resolution", default=2048, min=64, max=8192, subtype='PIXEL', update=_redraw,
        description="Shadow-map size of the first cascade in texels; "
                    "each next cascade is half as large unless Equal Resolution is on")
    equal_resolution: BoolProperty(
        name="Equal Resolution", default=False, update=_redraw,
        description="Give every cascade the first cascade's resolution: sharper far shadows, "
                    "at up to 4x the memory and fill of each halved cascade")
    stabilize: BoolProperty(
        name="Stabilize", default=True, update=_redraw,
        description="Fit each cascade with a bounding sphere and snap it to whole texels, so "
                    "shadow edges do not shimmer when the camera moves or turns. Off: tighter "
                    "fit (with Fit to Visible Depth, exactly the visible receivers), more "
                    "resolution, but edges swim")
    fade_out: BoolProperty(
        name="Fade Out", default=True, update=_redraw,
        description="Fade shadows out over the last part of the shadow distance instead of "
                    "stopping at a hard line")
    fade_fraction: FloatProperty(
        name="Fade Fraction", default=0.1, min=0.0, max=1.0, subtype='FACTOR', update=_redraw,
        description="Part of the shadow distance (0 to 1) over which shadows fade out. "
                    "Larger: a softer, longer fade")

    # --- Filtering ----------------------------------------------------------------------
    shadow_filter: EnumProperty(
        name="Shadow Filter", items=SHADOW_FILTERS, default='PCF', update=_redraw,
        description="How shadow edges are filtered: one hard tap, the fixed PCF kernel "
                    "below, or soft shadows whose penumbra widens with the distance to the "
                    "caster as the sun's Angle and a spot light's Radius say (PCSS)")
    pcf_radius: IntProperty(
        name="PCF Radius", default=1, min=0, max=8, update=_redraw,
        description="Percentage-closer filtering kernel radius in texels: 0 = single tap, "
                    "1 = 3x3, 2 = 5x5. Larger = softer edges, slower")
    pcf_sharpen: FloatProperty(
        name="PCF Sharpen", default=3.0, min=1.0, max=64.0, soft_max=16.0, update=_redraw,
        description="Multiplier (1 to 64) on the steepness of the filtered shadow edge "
                    "around its middle: the edge stays where the PCF kernel smooths it to, "
                    "but ramps this many times faster, and the kernel's faint spill onto lit "
                    "ground beside a shadow or a step (stripes) is cut. 1 = the kernel's own "
                    "ramp; 3 keeps the edge anti-aliased; from about 10 the edge is as hard "
                    "as one tap and PCF Radius hardly softens it. Alpha-hashed casters' "
                    "partial shadows are left as they are")
    pcf_pattern: EnumProperty(
        name="PCF Pattern", items=PCF_PATTERNS, default='GRID', update=_redraw,
        description="Which neighbour taps the filter takes within the PCF radius (texels). "
                    "Fewer taps: faster, more banding on soft edges")
    blend_band: FloatProperty(
        name="Blend Band", default=2.0, min=0.0, soft_max=100.0, unit='LENGTH', update=_redraw,
        description="Width (scene units of view depth) of the cross-fade before each split. "
                    "Inside it both cascades are sampled and mixed, so no seam shows. "
                    "0 = hard switch; capped at half of the nearer cascade's depth range. "
                    "With Cascade Selection: Shadow Map the cross-fade is at each map's "
                    "edge instead (0 still switches hard)")

    # --- Bias (texels: scaled per cascade by its world texel size) --------------------
    depth_bias: FloatProperty(
        name="Constant Bias", default=1.0, min=0.0, soft_max=10.0, update=_redraw,
        description="Depth offset in shadow texels, the same for all cascades (scaled to each "
                    "cascade's texel size). Too low: acne. Too high: peter-panning")
    slope_bias: FloatProperty(
        name="Slope Bias", default=0.5, min=0.0, soft_max=10.0, update=_redraw,
        description="Extra depth offset in texels that grows with the surface slope to the "
                    "sun. Too low: acne on surfaces the sun grazes. Too high: shadows detach")
    normal_offset: FloatProperty(
        name="Normal Offset", default=0.0, min=0.0, soft_max=10.0, update=_redraw,
        description="Moves the lookup point along the surface normal by this many texels. "
                    "Removes acne at grazing angles; too much shifts shadow edges")
    cull_front_faces: BoolProperty(
        name="Cull Front Faces", default=False, update=_redraw,
        description="Render back faces only into the shadow map (moves acne to the dark side; "
                    "needs closed meshes)")

    # --- Occluders ----------------------------------------------------------------------
    occluder_margin_auto: BoolProperty(
        name="Auto Margin", default=True, update=_redraw,
        description="Take the occluder margin from the scene bounds, so casters outside the "
                    "view are never clipped")
    occluder_margin: FloatProperty(
        name="Occluder Margin", default=100.0, min=0.0, soft_max=10000.0, unit='LENGTH',
        update=_redraw,
        description="How far (scene units) each cascade's near plane is pulled back toward "
                    "the sun, so casters outside the view still cast into it")

    # --- Anti-aliasing ----------------------------------------------------------------------
    # NOTE: 1 by default, with FXAA: a final render then is the viewport's image exactly,
    # at the viewport's cost (each sample is one more G-buffer and lighting pass: ~0.35 s
    # at 1280x720 on a CPU rasterizer). Raise it for stills, as EEVEE's render samples.
    render_samples: IntProperty(
        name="Render Samples", default=1, min=1, max=64, update=_redraw,
        description="Jittered frames averaged per final render (1 to 64), spread over Film > "
                    "Filter Size like EEVEE's render samples. More: smoother edges and "
                    "shadow edges, one more G-buffer and lighting pass each. 1: FXAA only")
    fxaa: BoolProperty(
        name="FXAA", default=True, update=_redraw,
        description="Post-process anti-aliasing (FXAA) in the viewport, and in final renders "
                    "with 1 render sample: smooths stair steps on edges for one cheap "
                    "full-screen pass; slightly softens fine texture detail")

    # --- Debug --------------------------------------------------------------------------
    debug_view: EnumProperty(
        name="Debug View", items=DEBUG_VIEWS, default='NONE', update=_redraw,
        description="What the engine shows: the lit image or a diagnostic view")
    debug_shadow_map: IntProperty(
        name="Shadow Map", default=0, min=0, max=11, update=_redraw,
        description="Which shadow map the Shadow map view shows: cascades first (0 = nearest), "
                    "then spot lights")
    debug_inset: BoolProperty(
        name="Inset", default=False, update=_redraw,
        description="Show the shadow map as an inset in the corner over the lit image")
    freeze_cascades: BoolProperty(
        name="Freeze Cascades", default=False, update=_redraw,
        description="Keep the cascade matrices while the camera moves and draw the cascade "
                    "boxes, to inspect the fit")

    # --- Lighting -------------------------------------------------------------------------
    ambient_strength: FloatProperty(
        name="Ambient", default=1.0, min=0.0, soft_max=10.0, update=_redraw,
        description="Multiplier (0 or more) on the World colour used as ambient light. "
                    "Higher: brighter shadows and flatter shading; 0: shadows are black")
    # NOTE: CSM keeps its own AO settings rather than reading EEVEE's (scene.eevee.gtao_*):
    # EEVEE's panel is hidden while CSM renders, and the settings moved between versions
    # (3.4's gtao_distance, deprecated in 4.2, gone in 5.0 for the horizon scan's
    # fast_gi_distance). Distance defaults to EEVEE's 0.2 m, the screen-space peer; Cycles'
    # World AO distance (10 m) is beyond what a screen-space search can see.
    ambient_occlusion: BoolProperty(
        name="Ambient Occlusion", default=True, update=_redraw,
        description="Darken the ambient (World) light where nearby surfaces hide the sky: "
                    "creases, corners and contacts, as Cycles' AO. Screen space, half "
                    "resolution; off skips the pass")
    ao_distance: FloatProperty(
        name="Distance", default=0.2, min=0.0, soft_max=100.0, unit='LENGTH',
        update=_redraw,
        description="How far (scene units) a surface can be and still occlude, as Cycles' "
                    "World AO distance. Larger: wider, softer darkening")
    ao_strength: FloatProperty(
        name="Strength", default=1.0, min=0.0, max=1.0, subtype='FACTOR', update=_redraw,
        description="How much of the occlusion is applied, 0 to 1: 0 = none, "
                    "1 = the full occlusion (as Cycles' AO pass)")
    # NOTE: the default keeps both worlds right at once: a scene built in Blender looks as
    # in EEVEE (inverse square, watts), an imported course scene as the course's programs.
    light_falloff: EnumProperty(
        name="Light Falloff", items=LIGHT_FALLOFFS, default='PER_LIGHT', update=_redraw,
        description="How point and spot lights dim with distance: physical (inverse square "
                    "of the Power in watts, as EEVEE), the course's linear falloff to the "
                    "light's radius, or per light (course lights linear, others physical)")


classes = (CSMSettings,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.csm = PointerProperty(type=CSMSettings)


def unregister():
    del bpy.types.Scene.csm
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
