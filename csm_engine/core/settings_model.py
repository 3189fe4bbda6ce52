"""The CSM render settings, described once: what each knob is called, means and allows.

Owns ``Setting`` (one knob on ``Scene.csm``: identifier, the label the panel shows, kind,
default, hard and soft range, subtype and unit, tooltip, enum items, panel group, when it
acts and whether presets set it), ``SETTINGS`` (every knob, in the order Blender and the
panels list them), ``is_active`` (whether a knob changes the picture under the other
settings: the panels grey it out when not, and its tooltip says why),
``PRESET_IDENTIFIERS`` (what a CSM preset sets), and ``Settings``, the frozen value object
the core reads: one field per setting, generated from ``SETTINGS`` so every default exists
only here. ``default_settings(**overrides)`` builds one for tests and tools.
``blender/settings.py`` builds the Blender properties from this table and
``blender/snapshot.py`` fills a ``Settings`` from them once per frame.

Defaults are chosen against peers (``docs/architecture.md``, ``../shared/docs/peers.md``)
and the course's assignment: 3 cascades of 2048/1024/512, hybrid splits, 3x3 PCF, a blend
band between cascades. Lambda and the biases were chosen with the ground-truth tool
(docs/ground-truth.md): with lambda 0.75 the 2048 map covered only empty foreground in the
course's camera, and a slope bias of 1 texel became several scene units in the 512 cascade
(missed contact shadows).

Enum identifiers are core's (``frame_layout``: the GLSL values are their positions); here
only their labels and tooltips. Standard library only.
"""

from dataclasses import dataclass, field, make_dataclass, replace
from types import MappingProxyType
from typing import Optional

from . import frame_layout

# Kinds of setting, named as Blender's RNA types (a vector is an RNA FLOAT array).
BOOLEAN = "BOOLEAN"
INT = "INT"
FLOAT = "FLOAT"
FLOAT_VECTOR = "FLOAT_VECTOR"
ENUM = "ENUM"
KINDS = (BOOLEAN, INT, FLOAT, FLOAT_VECTOR, ENUM)

# Panel groups, as ui.py labels its panels.
CASCADES = "Cascades"
FILTERING = "Filtering"
BIAS = "Bias"
OCCLUDERS = "Occluders"
ANTIALIASING = "Anti-Aliasing"
DEBUG = "Debug"
LIGHT = "Light"
GROUPS = (CASCADES, FILTERING, BIAS, OCCLUDERS, ANTIALIASING, DEBUG, LIGHT)

# The values a setting without a limit can still hold: Blender stores ints as int32 and
# floats as float32, so these are the bounds a value set past the UI is clamped to.
INT32_MIN, INT32_MAX = -2 ** 31, 2 ** 31 - 1
FLOAT32_MAX = 3.4028234663852886e+38


@dataclass(frozen=True)
class EnumItem:
    """One choice of an enum setting: its identifier (stored in .blend files and read by
    the core), the label the menu shows and its tooltip."""
    identifier: str
    label: str
    description: str


@dataclass(frozen=True)
class Condition:
    """A setting holds one of ``values`` (enum identifiers, booleans or whole numbers)."""
    identifier: str
    values: tuple


@dataclass(frozen=True)
class Setting:
    """One knob on ``Scene.csm``. ``name`` is the panel's label, short enough for the
    sidebar's default width; ``description`` (the tooltip) says it in full and ends with
    the reason the panel shows it inactive, if it can be. ``min``/``max`` are hard limits
    (None: the stored type's own range), ``soft_min``/``soft_max`` the slider's (None: the
    hard limits). ``subtype`` and ``unit`` are Blender's (None: plain number). ``items`` are
    an enum's choices. ``active_when``: alternatives, each a tuple of ``Condition`` that
    must all hold for the setting to change the picture (empty: it always does).
    ``preset``: presets set it (a method or quality knob, not a diagnostic view or the
    scene's own lighting)."""
    identifier: str
    name: str
    kind: str
    default: object
    group: str
    description: str
    min: Optional[float] = None
    max: Optional[float] = None
    soft_min: Optional[float] = None
    soft_max: Optional[float] = None
    subtype: Optional[str] = None
    unit: Optional[str] = None
    items: tuple = ()
    active_when: tuple = ()
    preset: bool = True

    @property
    def size(self):
        """Number of components of a vector setting, None for a single value."""
        return len(self.default) if self.kind == FLOAT_VECTOR else None

    @property
    def is_number(self):
        return self.kind in (INT, FLOAT, FLOAT_VECTOR)

    @property
    def hard_range(self):
        """(lowest, highest) value the setting may hold, None for non-numbers."""
        if not self.is_number:
            return None
        low, high = (INT32_MIN, INT32_MAX) if self.kind == INT else (-FLOAT32_MAX, FLOAT32_MAX)
        return (low if self.min is None else self.min, high if self.max is None else self.max)

    @property
    def soft_range(self):
        """(lowest, highest) value the slider offers, None for non-numbers."""
        if not self.is_number:
            return None
        low, high = self.hard_range
        return (low if self.soft_min is None else self.soft_min,
                high if self.soft_max is None else self.soft_max)

    @property
    def identifiers(self):
        """An enum's valid values, in order."""
        return tuple(item.identifier for item in self.items)

    @property
    def value_type(self):
        """The Python type of this setting's value in ``Settings``."""
        return {BOOLEAN: bool, INT: int, FLOAT: float, FLOAT_VECTOR: tuple, ENUM: str}[self.kind]


def _items(identifiers, **labels):
    """Enum items in core's order with their (label, tooltip)."""
    if set(identifiers) != set(labels):
        raise RuntimeError(f"settings labels {sorted(labels)} do not match {identifiers}")
    return tuple(EnumItem(identifier, *labels[identifier]) for identifier in identifiers)


def _when(**conditions):
    """One alternative of ``Setting.active_when``: every named setting holds one of its
    values (a single value or a tuple of them)."""
    return (tuple(Condition(identifier, values if isinstance(values, tuple) else (values,))
                  for identifier, values in conditions.items()),)


# Splits, their weights and the cascade choice only matter between two cascades.
_SEVERAL_CASCADES = MappingProxyType({"cascade_count": (2, 3, 4)})

# Labels are short enough for the 3D View sidebar's and the Properties editor's default
# widths (Blender cuts longer ones with an ellipsis); each tooltip starts with the full
# wording.
_SETTINGS = (
    # --- Cascades -----------------------------------------------------------------------
    Setting(
        "cascade_count", "Cascades", INT, 3, CASCADES, min=1, max=4,
        description="Number of shadow-map cascades covering the view depth (1 to 4). More: "
                    "sharper shadows near the camera, one more shadow pass each"),
    Setting(
        "resolution", "Resolution", INT, 2048, CASCADES, min=64, max=8192, subtype="PIXEL",
        description="Shadow-map size of the first cascade in texels; "
                    "each next cascade is half as large unless Equal Size is on"),
    Setting(
        "equal_resolution", "Equal Size", BOOLEAN, False, CASCADES,
        active_when=_when(**_SEVERAL_CASCADES),
        description="Equal resolution: give every cascade the first cascade's resolution: "
                    "sharper far shadows, at up to 4x the memory and fill of each halved "
                    "cascade"),
    Setting(
        "split_scheme", "Splits", ENUM, "HYBRID", CASCADES,
        active_when=_when(**_SEVERAL_CASCADES),
        items=_items(
            frame_layout.SPLIT_SCHEMES,
            UNIFORM=("Uniform", "Equal slices of view depth: sharp far away, blurry near the "
                                "camera"),
            LOG=("Logarithmic", "Slices grow geometrically with depth: even texel density on "
                                "screen, but the first slice is very thin"),
            HYBRID=("Hybrid", "Blend of logarithmic and uniform by Lambda "
                              "(z_i = L*n*(f/n)^(i/N) + (1-L)*(n + i/N*(f-n)))"),
            MANUAL=("Manual", "Split positions typed in (Split At) as fractions of the "
                              "shadow distance")),
        description="Split scheme: how the shadow distance is divided between cascades. "
                    "Logarithmic gives the near cascades short ranges (sharp close up), "
                    "uniform equal ranges (sharper far away)"),
    Setting(
        "split_lambda", "Lambda", FLOAT, 0.5, CASCADES, min=0.0, max=1.0, subtype="FACTOR",
        active_when=_when(split_scheme="HYBRID", fit_to_visible=False, **_SEVERAL_CASCADES),
        description="Hybrid split weight over clip start .. shadow distance (Fit to View "
                    "off), 0 to 1: 0 = uniform, 1 = logarithmic. Higher moves the splits "
                    "toward the camera: sharper near shadows, softer far ones"),
    Setting(
        "fitted_split_lambda", "Fit Lambda", FLOAT, 0.9, CASCADES, min=0.0, max=1.0,
        subtype="FACTOR",
        active_when=_when(split_scheme="HYBRID", fit_to_visible=True, **_SEVERAL_CASCADES),
        description="Lambda (fitted): hybrid split weight over the depth the camera sees "
                    "(Fit to View on), 0 to 1: 0 = uniform, 1 = logarithmic. That range "
                    "starts at the nearest visible surface, not at the clip start, so the "
                    "logarithmic split no longer spends the first cascade on empty "
                    "foreground, and a weight near 1 (sample-distribution shadow maps' "
                    "logarithmic split) gives the sharpest near shadows"),
    Setting(
        "manual_splits", "Split At", FLOAT_VECTOR, (0.1, 0.3, 0.6), CASCADES,
        min=0.0, max=1.0,
        active_when=_when(split_scheme="MANUAL", **_SEVERAL_CASCADES),
        description="Manual splits: far end of cascades 1..3 as fractions of the shadow "
                    "distance (must increase; only the first Cascades-1 are used)"),
    Setting(
        "fit_to_visible", "Fit to View", BOOLEAN, True, CASCADES,
        description="Fit to visible depth (sample-distribution shadow maps): the splits "
                    "divide the nearest to farthest depth the camera actually sees (measured "
                    "on the GPU each frame) instead of clip start to shadow distance, so no "
                    "cascade is spent on empty depth. Sharper shadows wherever the view "
                    "starts far away"),
    Setting(
        "shadow_distance", "Distance", FLOAT, 0.0, CASCADES, min=0.0,
        soft_max=10000.0, unit="LENGTH",
        description="Shadow distance: view depth (scene units) up to which the sun casts "
                    "shadows. 0 uses the camera's far clip"),
    Setting(
        "stabilize", "Stabilize", BOOLEAN, True, CASCADES,
        description="Fit each cascade with a bounding sphere and snap it to whole texels, so "
                    "shadow edges do not shimmer when the camera moves or turns. Off: tighter "
                    "fit (with Fit to View, exactly the visible receivers), more "
                    "resolution, but edges swim"),
    Setting(
        "fade_out", "Fade Out", BOOLEAN, True, CASCADES,
        description="Fade shadows out over the last part of the shadow distance instead of "
                    "stopping at a hard line"),
    Setting(
        "fade_fraction", "Fade Fraction", FLOAT, 0.1, CASCADES, min=0.0, max=1.0,
        subtype="FACTOR", active_when=_when(fade_out=True),
        description="Part of the shadow distance (0 to 1) over which shadows fade out. "
                    "Larger: a softer, longer fade"),
    Setting(
        "cascade_selection", "Selection", ENUM, "MAP", CASCADES,
        active_when=_when(**_SEVERAL_CASCADES),
        items=_items(
            frame_layout.CASCADE_SELECTIONS,
            MAP=("Shadow Map", "Each pixel reads the finest cascade whose shadow map holds "
                               "it, wherever its depth slice ends: a fitted cascade's map "
                               "also covers receivers beyond its split, so more of the view "
                               "gets the sharpest map (DirectX's Map Selection)"),
            DEPTH=("View Depth", "Each pixel reads the cascade whose slice of view depth "
                                 "holds it: the cascades show as bands at the splits "
                                 "(interval selection, the course's method)")),
        description="Cascade selection: how a pixel picks its cascade: the finest shadow "
                    "map that holds it, or the slice of view depth it lies in"),
    Setting(
        "blend_band", "Blend", FLOAT, 2.0, CASCADES, min=0.0, soft_max=100.0,
        unit="LENGTH", active_when=_when(cascade_selection="DEPTH", **_SEVERAL_CASCADES),
        description="Blend band: width (scene units of view depth) of the cross-fade before "
                    "each split. Inside it both cascades are sampled and mixed, so no seam "
                    "shows. 0 = hard switch; capped at half of the nearer cascade's depth "
                    "range. With Selection: Shadow Map the width hardly matters: above 0 "
                    "turns on a fixed 48-texel cross-fade at each map's edge, 0 switches "
                    "hard"),

    # --- Filtering ----------------------------------------------------------------------
    Setting(
        "shadow_filter", "Filter", ENUM, "PCF", FILTERING,
        items=_items(
            frame_layout.SHADOW_FILTERS,
            HARD=("Hard", "One shadow-map tap per pixel: texel-sized stair steps on edges"),
            PCF=("PCF", "Percentage-closer filtering with the fixed kernel below (Radius, "
                        "Pattern): the same softness everywhere"),
            SOFT=("Soft (light size)", "Penumbrae from the light's real size (sun Angle, "
                                       "spot Radius): sharp at contact, wider with distance, "
                                       "as in Cycles (PCSS: blocker search, then a variable "
                                       "filter)"),
            EXACT=("Exact (shadow volumes)", "Exact hard shadows, counted per pixel through "
                                             "shadow volumes as a ray cast would see them: "
                                             "no biases, no resolution. The sun and the first "
                                             "three shadowed point or spot lights; further "
                                             "lights keep their maps' hard tap. Casters with "
                                             "an alpha-clipped or hashed shadow cast none")),
        description="Shadow filter: how shadow edges are filtered: one hard tap, the fixed "
                    "PCF kernel below, soft shadows whose penumbra widens with the "
                    "distance to the caster as the sun's Angle and a spot light's Radius say "
                    "(PCSS), or exact hard shadows by shadow volumes"),
    Setting(
        "pcf_radius", "Radius", INT, 1, FILTERING, min=0, max=8,
        active_when=_when(shadow_filter="PCF"),
        description="PCF radius: percentage-closer filtering kernel radius in texels: "
                    "0 = single tap, 1 = 3x3, 2 = 5x5. Larger = softer edges, slower"),
    Setting(
        "pcf_sharpen", "Sharpen", FLOAT, 3.0, FILTERING, min=1.0, max=64.0,
        soft_max=16.0, active_when=_when(shadow_filter="PCF"),
        description="PCF sharpen: multiplier (1 to 64) on the steepness of the filtered "
                    "shadow edge around its middle: the edge stays where the PCF kernel "
                    "smooths it to, but ramps this many times faster, and the kernel's faint "
                    "spill onto lit ground beside a shadow or a step (stripes) is cut. 1 = "
                    "the kernel's own ramp; 3 keeps the edge anti-aliased; from about 10 the "
                    "edge is as hard as one tap and Radius hardly softens it. Alpha-hashed "
                    "casters' partial shadows are left as they are"),
    Setting(
        "pcf_pattern", "Pattern", ENUM, "GRID", FILTERING,
        active_when=_when(shadow_filter="PCF"),
        items=_items(
            frame_layout.PCF_PATTERNS,
            GRID=("Grid", "Square kernel of (2r+1)x(2r+1) taps; radius 0 is a single tap"),
            CROSS5=("5-tap cross", "Centre and 4 neighbours one texel away, scaled by the "
                                   "radius"),
            NINE_TAP=("9-tap", "Centre, 4 edges and 4 corners, scaled by the radius")),
        description="PCF pattern: which neighbour taps the filter takes within the PCF "
                    "radius (texels). Fewer taps: faster, more banding on soft edges"),

    # --- Bias (texels: scaled per cascade by its world texel size) --------------------
    Setting(
        "depth_bias", "Constant", FLOAT, 1.0, BIAS, min=0.0, soft_max=10.0,
        description="Constant bias: depth offset in shadow-map texels, the same for all "
                    "cascades (scaled to each cascade's texel size). Too low: acne. Too "
                    "high: peter-panning"),
    Setting(
        "slope_bias", "Slope", FLOAT, 0.5, BIAS, min=0.0, soft_max=10.0,
        description="Slope bias: extra depth offset in shadow-map texels that grows with "
                    "the surface slope to the sun. Too low: acne on surfaces the sun "
                    "grazes. Too high: shadows detach"),
    Setting(
        "normal_offset", "Normal", FLOAT, 0.0, BIAS, min=0.0, soft_max=10.0,
        description="Normal offset: moves the lookup point along the surface normal by this "
                    "many shadow-map texels. Removes acne at grazing angles; too much shifts "
                    "shadow edges"),
    Setting(
        "cull_front_faces", "Cull Front", BOOLEAN, False, BIAS,
        description="Cull front faces: render back faces only into the shadow map (moves "
                    "acne to the dark side; needs closed meshes)"),

    # --- Occluders ----------------------------------------------------------------------
    Setting(
        "occluder_margin_auto", "Auto Margin", BOOLEAN, True, OCCLUDERS,
        description="Take the occluder margin from the scene bounds, so casters outside the "
                    "view are never clipped"),
    Setting(
        "occluder_margin", "Margin", FLOAT, 100.0, OCCLUDERS, min=0.0,
        soft_max=10000.0, unit="LENGTH", active_when=_when(occluder_margin_auto=False),
        description="Occluder margin: how far (scene units) each cascade's near plane is "
                    "pulled back toward the sun, so casters outside the view still cast "
                    "into it"),

    # --- Anti-aliasing --------------------------------------------------------------------
    # 1 by default, with FXAA: a final render then is the viewport's image exactly, at the
    # viewport's cost (each sample is one more G-buffer and lighting pass: ~0.35 s at
    # 1280x720 on a CPU rasterizer). Raise it for stills, as EEVEE's render samples.
    Setting(
        "render_samples", "Samples", INT, 1, ANTIALIASING, min=1, max=64,
        description="Render samples: jittered frames averaged per final render (1 to 64), "
                    "spread over Film > Filter Size like EEVEE's render samples. More: "
                    "smoother edges and shadow edges, one more G-buffer and lighting pass "
                    "each. 1: FXAA only"),
    Setting(
        "fxaa", "FXAA", BOOLEAN, True, ANTIALIASING,
        description="Post-process anti-aliasing (FXAA) in the viewport, and in final renders "
                    "with 1 render sample: smooths stair steps on edges for one cheap "
                    "full-screen pass; slightly softens fine texture detail"),

    # --- Debug --------------------------------------------------------------------------
    Setting(
        "debug_view", "View", ENUM, "NONE", DEBUG, preset=False,
        items=_items(
            frame_layout.DEBUG_VIEWS,
            NONE=("Lit", "The normal lit image"),
            CASCADES=("Cascades", "Tint by cascade: red nearest, green, blue, yellow "
                                         "farthest"),
            SHADOW_FACTOR=("Shadow factor", "Sun visibility only: white lit, black shadowed"),
            SHADOW_MAP=("Shadow map", "Linearized depth of one shadow map"),
            TEXEL_DENSITY=("Texel density", "Shadow-map texels per screen pixel as a heat "
                                            "map: blue = wasted resolution, red = too few "
                                            "texels"),
            ALBEDO=("G-buffer: albedo", "Base colour channel of the G-buffer"),
            NORMAL=("G-buffer: normal", "World-space normals mapped to 0..1"),
            POSITION=("G-buffer: position", "World position in repeating bands 1/20 of the "
                                            "shadow distance wide"),
            DEPTH=("G-buffer: depth", "View depth, normalised to the shadow distance"),
            SPECULAR=("G-buffer: specular", "Specular level (red: 0.5 is 4% reflectance), "
                                            "roughness (green), metallic (blue)"),
            AMBIENT_OCCLUSION=("Ambient occlusion", "The factor the ambient light is "
                                                    "multiplied by: white open, black fully "
                                                    "occluded"),
            SHADOW_ERROR=("Shadow error", "Where the Filter's sun shadow disagrees with the "
                                          "exact one (shadow volumes): red a false shadow, "
                                          "cyan a missed one, grey where they agree; the "
                                          "share of surface pixels wrong is in the legend")),
        description="Debug view: what the engine shows: the lit image or a diagnostic view"),
    Setting(
        "debug_shadow_map", "Map", INT, 0, DEBUG, min=0, max=11, preset=False,
        active_when=_when(debug_view="SHADOW_MAP") + _when(debug_inset=True),
        description="Which shadow map the Shadow map view and the Inset show: cascades "
                    "first (0 = nearest), then spot lights"),
    Setting(
        "debug_inset", "Inset", BOOLEAN, False, DEBUG, preset=False,
        description="Show the shadow map as an inset in the corner over the lit image"),
    Setting(
        "freeze_cascades", "Freeze", BOOLEAN, False, DEBUG, preset=False,
        description="Freeze cascades: keep the cascade matrices while the camera moves and "
                    "draw the cascade boxes, to inspect the fit"),

    # --- Lighting -------------------------------------------------------------------------
    Setting(
        "ambient_strength", "Ambient", FLOAT, 1.0, LIGHT, min=0.0, soft_max=10.0,
        preset=False,
        description="Multiplier (0 or more) on the World colour used as ambient light. "
                    "Higher: brighter shadows and flatter shading; 0: shadows are black"),
    # CSM keeps its own AO settings rather than reading EEVEE's (scene.eevee.gtao_*):
    # EEVEE's panel is hidden while CSM renders, and the settings moved between versions
    # (3.4's gtao_distance, deprecated in 4.2, gone in 5.0 for the horizon scan's
    # fast_gi_distance). Distance defaults to EEVEE's 0.2 m, the screen-space peer; Cycles'
    # World AO distance (10 m) is beyond what a screen-space search can see.
    Setting(
        "ambient_occlusion", "Occlusion", BOOLEAN, True, LIGHT,
        description="Ambient occlusion: darken the ambient (World) light where nearby "
                    "surfaces hide the sky: creases, corners and contacts, as Cycles' AO. "
                    "Screen space, half resolution; off skips the pass"),
    Setting(
        "ao_distance", "Distance", FLOAT, 0.2, LIGHT, min=0.0, soft_max=100.0, unit="LENGTH",
        active_when=_when(ambient_occlusion=True),
        description="Occlusion distance: how far (scene units) a surface can be and still "
                    "occlude, as Cycles' World AO distance. Larger: wider, softer darkening"),
    Setting(
        "ao_strength", "Strength", FLOAT, 1.0, LIGHT, min=0.0, max=1.0, subtype="FACTOR",
        active_when=_when(ambient_occlusion=True),
        description="Occlusion strength: how much of the occlusion is applied, 0 to 1: "
                    "0 = none, 1 = the full occlusion (as Cycles' AO pass)"),
    # The default keeps both worlds right at once: a scene built in Blender looks as in
    # EEVEE (inverse square, watts), an imported course scene as the course's programs.
    # 'PER_LIGHT' is not a falloff of its own (so not in frame_layout): snapshot.py picks
    # one of the others per light.
    Setting(
        "light_falloff", "Falloff", ENUM, "PER_LIGHT", LIGHT, preset=False,
        items=(EnumItem("PER_LIGHT", "Per light",
                        "Lights imported from a course scene file (they carry the custom "
                        "property csm_radius) fall off linearly to their radius; every other "
                        "light is physical, as in EEVEE"),) + _items(
            frame_layout.LIGHT_FALLOFFS,
            PHYSICAL=("Physical", "Inverse square, as in EEVEE and Cycles: a point or spot "
                                  "light's Power in watts, cut off smoothly at Custom "
                                  "Distance or where it falls below EEVEE's Light Threshold"),
            LINEAR_RADIUS=("Linear to radius", "The course's falloff: full strength at the "
                                               "light, linearly to zero at its radius (Custom "
                                               "Distance); 100 W shines with exactly the "
                                               "light's colour")),
        description="Light falloff: how point and spot lights dim with distance: physical "
                    "(inverse square of the Power in watts, as EEVEE), the course's linear "
                    "falloff to the light's radius, or per light (course lights linear, "
                    "others physical)"),
)


def _value_text(setting, values):
    """How the inactive-reason sentence names ``values`` of ``setting``."""
    if setting.kind == BOOLEAN:
        return "on" if values == (True,) else "off"
    if setting.kind == ENUM:
        labels = {item.identifier: item.label for item in setting.items}
        return " or ".join(labels[value] for value in values)
    if setting.kind == INT and values == tuple(range(min(values), setting.hard_range[1] + 1)):
        return f"{min(values)} or more"
    return " or ".join(str(value) for value in values)


def _inactive_reason(setting, by_identifier):
    """'Inactive unless ...' for a setting with ``active_when``, in the panel's labels."""
    alternatives = []
    for alternative in setting.active_when:
        parts = []
        for condition in alternative:
            other = by_identifier[condition.identifier]
            parts.append(f"{other.name} is {_value_text(other, condition.values)}")
        alternatives.append(" and ".join(parts))
    return "Inactive unless " + ", or ".join(alternatives)


def _with_inactive_reasons(settings):
    # The tooltip is the only place Blender lets a panel explain a greyed-out control, so
    # the reason is part of the description, written from the same conditions the panel
    # tests (one source for both).
    by_identifier = {setting.identifier: setting for setting in settings}
    return tuple(
        replace(setting, description=f"{setting.description}. "
                                     f"{_inactive_reason(setting, by_identifier)}")
        if setting.active_when else setting for setting in settings)


SETTINGS = _with_inactive_reasons(_SETTINGS)

# identifier -> Setting, read-only.
BY_IDENTIFIER = MappingProxyType({setting.identifier: setting for setting in SETTINGS})

# The settings a preset sets, in the model's order.
PRESET_IDENTIFIERS = tuple(setting.identifier for setting in SETTINGS if setting.preset)


def is_active(setting, values):
    """Whether ``setting`` changes the picture under ``values`` (anything with one attribute
    per setting identifier: a ``Settings`` or Blender's ``Scene.csm``)."""
    return not setting.active_when or any(
        all(getattr(values, condition.identifier) in condition.values
            for condition in alternative)
        for alternative in setting.active_when)


def _settings_class():
    fields = [(s.identifier, s.value_type, field(default=s.default)) for s in SETTINGS]
    cls = make_dataclass("Settings", fields, frozen=True, namespace={"__doc__": (
        "The CSM settings of one frame as plain, immutable values: one field per "
        "``SETTINGS`` entry, defaulting to its default. Floats are Python floats, a vector "
        "a tuple, an enum its identifier. Change one with ``dataclasses.replace``.")})
    cls.__module__ = __name__
    return cls


Settings = _settings_class()


def default_settings(**overrides):
    """The default ``Settings`` with ``overrides`` (setting identifier = value) applied;
    a name that is no setting is a TypeError. A vector may be given as any sequence."""
    unknown = sorted(set(overrides) - set(BY_IDENTIFIER))
    if unknown:
        raise TypeError(f"not a CSM setting: {', '.join(unknown)}")
    for name, value in overrides.items():
        if BY_IDENTIFIER[name].kind == FLOAT_VECTOR:
            overrides[name] = tuple(float(v) for v in value)
    return Settings(**overrides)
