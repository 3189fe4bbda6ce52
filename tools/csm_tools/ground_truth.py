"""Ground truth for CSM's sun shadows: the same scene ray traced by Cycles, and EEVEE beside CSM.

Owns the comparison tool ``./dev ground-truth scene.json`` (``python -m
csm_tools.ground_truth``). It renders the scene with CSM, with EEVEE and with Cycles on the
CPU, in one process, each twice: once with the sun's shadows on and once with them off.
Sun visibility is the ratio on / off per pixel, so intensity, BRDF and colour differences
between the engines cancel and only the shadow test remains (docs/ground-truth.md). Every
number is given for CSM and for EEVEE against the same Cycles reference, side by side.

Two modes:
- **hard** (the default, ``--sun-angle 0``): the sun's angle is 0; Cycles takes 1 sample
  through the pixel centre (a Gaussian pixel filter of width 0.01, where CSM's rasterizer
  also samples), no bounces, black world: exact hard shadows. EEVEE renders 1 sample.
- **soft** (``--sun-angle DEG``): the sun's Angle is DEG for every engine; Cycles takes
  enough samples for a clean continuous visibility (``SOFT_CYCLES_SAMPLES``, measured), EEVEE
  renders ``SOFT_EEVEE_SAMPLES`` with its soft shadows on, and CSM gets
  ``shadow_filter = 'SOFT'`` when that setting exists and ``--set`` does not name it.

Reported per engine (``Comparison``): the hard classification (visibility < 0.5 is
shadowed: false / missed shadow, mismatch), the continuous error (mean absolute and mean
signed visibility error), the penumbra width (pixels with 0.05 < visibility < 0.95, relative
to Cycles'), partial shadow on fully lit pixels (Cycles >= 0.999, engine < 0.999) and the
share of fully lit flat ground (normal within 1 degree of +Z) the engine shows at >= 0.999.
In hard mode flat lit ground is also judged on the pixels whose *whole area* Cycles shows
lit (``cycles_whole_pixel_lit``: Cycles again through a 1-pixel box filter): a pixel that a
shadow edge crosses is lit at its centre but not fully lit, and any anti-aliasing filter
(CSM's PCF, Cycles' own pixel filter) rightly shows it partly shadowed.
For CSM alone, the texel density (``TexelDensity``): how many screen pixels one shadow texel
of the pixel's cascade covers, from the render's shadow plan, its cascade channel and its
world positions.

A pixel is compared when every measured engine lights it with shadows off (``off`` above a
small fraction of the image's typical brightness): background, surfaces facing away from
the sun and grazing surfaces are excluded. Every light but the sun CSM shades with is
hidden and the world is black for all engines; the scene's camera and CSM settings are
kept (debug views are switched off for the measurement). Everything the tool changes on
the scene is restored afterwards.

CSM also writes its sun visibility into the auxiliary target (``aux[..., 0]``); the tool
compares that channel with CSM's own on/off ratio, which proves the ratio method measures
what the shader computes.

``--all`` runs the documented suite (bundled scenes, a displaced-grid terrain under a low
sun, the monastery model when it can be fetched; hard mode and soft mode at 1, 3 and 10
degrees) and rewrites the generated tables of docs/ground-truth.md.

The statistics and the heat maps are plain numpy (PNGs through ``report_io``); Blender is
imported only inside the functions that render.
"""

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

from csm_engine.blender.cli import (CLIError, EXIT_RENDER, EXIT_SCENE, apply_override,
                                    open_scene, parse_resolution, run_reporting_errors)

from . import report_io
from .report_io import write_png

SHADOWED_BELOW = 0.5            # visibility under this counts as "in shadow"
FULLY_LIT = 0.999               # at or above: fully lit ("partial shadow on lit pixels")
PENUMBRA = (0.05, 0.95)         # strictly between: a penumbra pixel
FLAT_GROUND_DEGREES = 1.0       # "flat ground": the normal within this of +Z
LIT_FRACTION = 1e-3             # compared when off > this x the 99th percentile of off
DEFAULT_RESOLUTION = "1280x720"
SOFT_RESOLUTION = "640x360"     # --all's soft sweeps (Cycles' many samples cost minutes)
ALL_SUN_ANGLES = (1.0, 3.0, 10.0)
TRANSPARENT_BOUNCES = 64        # alpha-cut layers a Cycles shadow ray may pass through
# NOTE: Cycles' samples in soft mode, picked by measuring the noise (docs/ground-truth.md,
# "Soft mode: how many samples"): on default.json at 3 degrees, two seeds differ by a mean
# absolute visibility of 0.0021 / 0.0010 / 0.0005 at 16 / 64 / 256 samples; 128 keeps one
# render's noise near 0.0005, a tenth of the engines' errors, at about a minute per render.
SOFT_CYCLES_SAMPLES = 128
SOFT_EEVEE_SAMPLES = 16         # EEVEE's soft shadows converge over its render samples
# NOTE: samples over each pixel's area for the whole-pixel-lit mask, measured
# (docs/ground-truth.md, Method 7, "whole pixel lit"): point_lights' flat lit ground at
# >= 0.999 reads 0.99940 with 16 and 0.99951 with 64. A sliver of shadow under 1/16 of a
# pixel can slip between 16 stratified samples; such a pixel counts as whole-lit, so fewer
# samples can only make the figure stricter on the engines.
WHOLE_PIXEL_SAMPLES = 16
PROG = "./dev ground-truth"
BEGIN, END = f"<!-- BEGIN GENERATED BY {PROG} --all -->", "<!-- END GENERATED -->"

# Heat-map colours (sRGB bytes).
COLOR_EXCLUDED = (0, 0, 0)          # background, unlit, facing away from the sun
COLOR_AGREE_LIT = (200, 200, 200)
COLOR_AGREE_SHADOW = (90, 90, 90)
COLOR_FALSE_SHADOW = (230, 30, 30)  # engine shadowed, Cycles lit: acne, overlapping casters
COLOR_MISSED_SHADOW = (40, 90, 255)  # engine lit, Cycles shadowed: peter-panning, clipping
COLOR_LIT_BY_ONE = (200, 170, 0)    # only one engine lights the pixel: silhouettes, normals
SIGNED_ERROR_FULL = 0.5             # soft heat map: this |error| is fully red / blue


@dataclasses.dataclass
class Comparison:
    """One engine against Cycles. Percentages are of the compared pixels unless named
    otherwise; visibility errors are in visibility units (0..1)."""
    width: int
    height: int
    compared_pixels: int
    false_shadow_pixels: int
    missed_shadow_pixels: int
    lit_by_one_pixels: int         # lit (shadows off) in this engine or Cycles only
    cycles_shadowed_pixels: int
    csm_shadowed_pixels: int       # the engine's shadowed pixels (the name predates EEVEE)
    # CSM's aux visibility channel against CSM's own on/off ratio, on compared pixels.
    aux_classified_differently: int = 0
    aux_max_difference: float = 0.0
    engine: str = "CSM"
    mean_abs_error: float = 0.0    # mean |engine - Cycles| visibility over compared pixels
    mean_signed_error: float = 0.0  # mean (engine - Cycles): < 0 too dark, > 0 too light
    penumbra_pixels: int = 0       # 0.05 < engine visibility < 0.95
    cycles_penumbra_pixels: int = 0
    cycles_fully_lit_pixels: int = 0   # Cycles visibility >= 0.999
    partial_on_lit_pixels: int = 0     # ... where the engine's is < 0.999
    flat_lit_ground_pixels: int = 0    # fully lit in Cycles, normal within 1 deg of +Z
    flat_lit_ground_full_pixels: int = 0   # ... where the engine's visibility >= 0.999
    # Of the flat lit ground short of 0.999, the pixels next to (8-neighbour of) one that
    # Cycles shows shadowed: a shadow edge's filter reach, not a stripe or a bias.
    flat_lit_ground_short_at_edge_pixels: int = 0
    # All flat lit ground next to a pixel Cycles shows shadowed (short of 0.999 or not).
    flat_lit_ground_at_edge_pixels: int = 0
    # Flat lit ground whose whole pixel area Cycles shows lit (hard mode; 0 without the
    # whole-pixel reference), and of it the pixels the engine shows at >= 0.999.
    flat_whole_lit_ground_pixels: int = 0
    flat_whole_lit_ground_full_pixels: int = 0
    seconds: float = 0.0           # the engine's shadows-on render, warm (wall clock)

    @property
    def false_shadow_percent(self):
        return 100.0 * self.false_shadow_pixels / max(self.compared_pixels, 1)

    @property
    def missed_shadow_percent(self):
        return 100.0 * self.missed_shadow_pixels / max(self.compared_pixels, 1)

    @property
    def mismatch_percent(self):
        return self.false_shadow_percent + self.missed_shadow_percent

    @property
    def shadow_lost_percent(self):
        """Missed shadow as a share of Cycles' shadowed pixels: thin casters whose whole
        shadow disappears barely move the mismatch but show here."""
        return 100.0 * self.missed_shadow_pixels / max(self.cycles_shadowed_pixels, 1)

    @property
    def penumbra_width_ratio(self):
        """Penumbra pixels relative to Cycles': 1 is right, < 1 too sharp, > 1 too wide.
        None when Cycles has (almost) no penumbra (hard mode)."""
        if self.cycles_penumbra_pixels < 20:
            return None
        return self.penumbra_pixels / self.cycles_penumbra_pixels

    @property
    def penumbra_width_error_percent(self):
        """(penumbra pixels / Cycles' - 1) in %: signed, 0 is right."""
        ratio = self.penumbra_width_ratio
        return None if ratio is None else 100.0 * (ratio - 1.0)

    @property
    def partial_on_lit_percent(self):
        """Of Cycles' fully lit compared pixels, the share the engine shows below 0.999."""
        return 100.0 * self.partial_on_lit_pixels / max(self.cycles_fully_lit_pixels, 1)

    @property
    def flat_ground_short_at_edge_fraction(self):
        """Of the fully lit flat ground the engine shows below 0.999, the fraction that
        touches a pixel Cycles shows shadowed (None when none falls short)."""
        short = self.flat_lit_ground_pixels - self.flat_lit_ground_full_pixels
        if short <= 0:
            return None
        return self.flat_lit_ground_short_at_edge_pixels / short

    @property
    def flat_ground_away_from_edges_full_fraction(self):
        """The same as ``flat_ground_full_fraction`` without the pixels next to one Cycles
        shows shadowed: the first pixel beside a shadow edge, which any anti-aliasing
        filter leaves partly shadowed while a point-sampled Cycles pixel is lit or not.
        What stays short here is stripes, acne and spill further out (None when the view
        has no such ground)."""
        away = self.flat_lit_ground_pixels - self.flat_lit_ground_at_edge_pixels
        if away <= 0:
            return None
        short_away = (self.flat_lit_ground_pixels - self.flat_lit_ground_full_pixels
                      - self.flat_lit_ground_short_at_edge_pixels)
        return 1.0 - short_away / away

    @property
    def flat_ground_whole_pixel_full_fraction(self):
        """Of the flat ground whose whole pixel Cycles shows lit (no shadow edge crosses
        it), the fraction the engine shows at >= 0.999: the target's "fully lit flat ground"
        without the pixels a shadow edge crosses (None without the whole-pixel reference or
        without such ground)."""
        if self.flat_whole_lit_ground_pixels == 0:
            return None
        return self.flat_whole_lit_ground_full_pixels / self.flat_whole_lit_ground_pixels

    @property
    def flat_ground_full_fraction(self):
        """Of the fully lit flat ground, the fraction the engine shows at >= 0.999 (None
        when the view has no flat ground)."""
        if self.flat_lit_ground_pixels == 0:
            return None
        return self.flat_lit_ground_full_pixels / self.flat_lit_ground_pixels

    def as_dict(self):
        values = dataclasses.asdict(self)
        for name in ("mismatch_percent", "false_shadow_percent", "missed_shadow_percent",
                     "shadow_lost_percent", "penumbra_width_ratio",
                     "penumbra_width_error_percent", "partial_on_lit_percent",
                     "flat_ground_full_fraction", "flat_ground_short_at_edge_fraction",
                     "flat_ground_away_from_edges_full_fraction",
                     "flat_ground_whole_pixel_full_fraction"):
            values[name] = getattr(self, name)
        return values

    def summary(self):
        total = self.width * self.height
        return "\n".join([
            f"compared pixels: {self.compared_pixels} of {total} "
            f"({100.0 * self.compared_pixels / max(total, 1):.1f} %); "
            f"shadowed: Cycles {self.cycles_shadowed_pixels}, {self.engine} "
            f"{self.csm_shadowed_pixels}",
            f"mismatch: {self.mismatch_percent:.3f} %  (false shadow "
            f"{self.false_shadow_percent:.3f} %, missed shadow "
            f"{self.missed_shadow_percent:.3f} %)",
            f"of Cycles' shadowed pixels, {self.engine} shows lit: "
            f"{self.shadow_lost_percent:.1f} %",
            f"lit by one engine only (not compared): {self.lit_by_one_pixels} pixels",
            f"{self.engine} aux visibility vs {self.engine} on/off ratio: "
            f"{self.aux_classified_differently} pixels classified differently, max "
            f"difference {self.aux_max_difference:.2g}",
        ])


@dataclasses.dataclass
class TexelDensity:
    """CSM's shadow-map resolution on screen. The *texel footprint* of a pixel is the
    world size of one shadow texel of the pixel's cascade (``ShadowTile.texel_world``)
    divided by the pixel's own world size on the surface (the larger of its two screen
    neighbours' distances, as the Texel Density debug view's ``dFdx``/``dFdy``): how many
    pixels one texel spans. 1 = one texel per pixel; 4 = a texel is 4 pixels wide (blocky
    edges); 0.25 = 4 texels per pixel (resolution wasted). Lower is sharper."""
    pixels: int
    median_footprint_px: float
    p10_footprint_px: float
    p90_footprint_px: float          # the coarsest tenth of the picture
    cascade_share: list              # fraction of the measured pixels in each cascade
    texel_world: list                # scene units per texel, per cascade

    def as_dict(self):
        return dataclasses.asdict(self)


# --------------------------------------------------------------------------- pure numpy

def lit_mask(off):
    """Pixels a sun without shadows lights: ``off`` (H, W) above a small fraction of the
    image's typical lit value (relative, so each engine's own brightness scale works)."""
    positive = off[off > 0.0]
    if positive.size == 0:
        return np.zeros(off.shape, dtype=bool)
    return off > LIT_FRACTION * np.percentile(positive, 99.0)


def visibility_from_on_off(on, off):
    """Per-pixel sun visibility on / off, 1 where the pixel is unlit anyway."""
    vis = np.ones(off.shape, dtype=np.float64)
    lit = off > 0.0
    vis[lit] = on[lit] / off[lit]
    return np.clip(vis, 0.0, 1.0)


def compare(csm_vis, cycles_vis, csm_lit, cycles_lit, also_lit=None, flat=None,
            whole_lit=None):
    """Classify every pixel of one engine (``csm_*``, any engine) against Cycles and
    measure the continuous errors; returns (Comparison, class image). Compared pixels are
    lit in both and in ``also_lit`` (the other engines measured in the same run, so every
    engine is judged on the same pixels). ``flat`` marks flat ground (H, W bool);
    ``whole_lit`` the pixels whose whole area Cycles shows lit (H, W bool, or None).
    Classes: 0 excluded, 1 agree lit, 2 agree shadowed, 3 false shadow, 4 missed shadow,
    5 lit by one only."""
    compared = csm_lit & cycles_lit
    if also_lit is not None:
        compared &= also_lit
    csm_dark = csm_vis < SHADOWED_BELOW
    cycles_dark = cycles_vis < SHADOWED_BELOW
    classes = np.zeros(csm_vis.shape, dtype=np.uint8)
    classes[csm_lit ^ cycles_lit] = 5
    classes[compared & ~csm_dark & ~cycles_dark] = 1
    classes[compared & csm_dark & cycles_dark] = 2
    classes[compared & csm_dark & ~cycles_dark] = 3
    classes[compared & ~csm_dark & cycles_dark] = 4
    height, width = csm_vis.shape
    error = (csm_vis - cycles_vis)[compared]
    low, high = PENUMBRA
    fully_lit = compared & (cycles_vis >= FULLY_LIT)
    flat_lit = fully_lit & flat if flat is not None else np.zeros_like(compared)
    next_to_shadow = _next_to(cycles_lit & cycles_dark)
    flat_whole_lit = flat_lit & whole_lit if whole_lit is not None \
        else np.zeros_like(compared)
    result = Comparison(
        width=width, height=height, compared_pixels=int(compared.sum()),
        false_shadow_pixels=int((classes == 3).sum()),
        missed_shadow_pixels=int((classes == 4).sum()),
        lit_by_one_pixels=int((classes == 5).sum()),
        cycles_shadowed_pixels=int((compared & cycles_dark).sum()),
        csm_shadowed_pixels=int((compared & csm_dark).sum()),
        mean_abs_error=float(np.abs(error).mean()) if error.size else 0.0,
        mean_signed_error=float(error.mean()) if error.size else 0.0,
        penumbra_pixels=int((compared & (csm_vis > low) & (csm_vis < high)).sum()),
        cycles_penumbra_pixels=int((compared & (cycles_vis > low) & (cycles_vis < high)).sum()),
        cycles_fully_lit_pixels=int(fully_lit.sum()),
        partial_on_lit_pixels=int((fully_lit & (csm_vis < FULLY_LIT)).sum()),
        flat_lit_ground_pixels=int(flat_lit.sum()),
        flat_lit_ground_full_pixels=int((flat_lit & (csm_vis >= FULLY_LIT)).sum()),
        flat_lit_ground_short_at_edge_pixels=int(
            (flat_lit & (csm_vis < FULLY_LIT) & next_to_shadow).sum()),
        flat_lit_ground_at_edge_pixels=int((flat_lit & next_to_shadow).sum()),
        flat_whole_lit_ground_pixels=int(flat_whole_lit.sum()),
        flat_whole_lit_ground_full_pixels=int(
            (flat_whole_lit & (csm_vis >= FULLY_LIT)).sum()))
    return result, classes


def _next_to(mask):
    """``mask`` grown by one pixel in all eight directions."""
    grown = mask.copy()
    grown[1:] |= mask[:-1]
    grown[:-1] |= mask[1:]
    rows = grown.copy()
    grown[:, 1:] |= rows[:, :-1]
    grown[:, :-1] |= rows[:, 1:]
    return grown


def heatmap(classes):
    """(H, W, 3) uint8 colours for a class image."""
    palette = np.array([COLOR_EXCLUDED, COLOR_AGREE_LIT, COLOR_AGREE_SHADOW,
                        COLOR_FALSE_SHADOW, COLOR_MISSED_SHADOW, COLOR_LIT_BY_ONE],
                       dtype=np.uint8)
    return palette[classes]


def signed_error_heatmap(vis, cycles_vis, classes):
    """(H, W, 3) uint8 for soft mode: Cycles' visibility as grey (agree-lit grey at 1,
    agree-shadow grey at 0), tinted red where the engine is darker than Cycles and blue
    where it is lighter, fully at |error| >= 0.5. Excluded pixels black, lit by one yellow."""
    dark, light = (np.array(c, dtype=np.float64) for c in (COLOR_AGREE_SHADOW,
                                                           COLOR_AGREE_LIT))
    base = dark + (light - dark) * cycles_vis[..., None]
    error = vis - cycles_vis
    amount = np.clip(np.abs(error) / SIGNED_ERROR_FULL, 0.0, 1.0)[..., None]
    tint = np.where((error < 0.0)[..., None], np.array(COLOR_FALSE_SHADOW, np.float64),
                    np.array(COLOR_MISSED_SHADOW, np.float64))
    image = base * (1.0 - amount) + tint * amount
    image[classes == 0] = COLOR_EXCLUDED
    image[classes == 5] = COLOR_LIT_BY_ONE
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def pixel_world_size(position, covered):
    """(H, W) world size of each pixel on its surface: the larger over x and y of the
    distance to the nearer covered neighbour (forward or backward, so a silhouette's jump
    to the background or to a far surface is skipped). NaN where a direction has no
    covered neighbour."""
    sizes = []
    for axis in (1, 0):
        step = np.linalg.norm(np.diff(position, axis=axis), axis=2)
        both = covered[:, 1:] & covered[:, :-1] if axis == 1 else covered[1:] & covered[:-1]
        step = np.where(both, step, np.nan)
        pad_ahead, pad_behind = [(0, 0), (0, 0)], [(0, 0), (0, 0)]
        pad_ahead[axis], pad_behind[axis] = (0, 1), (1, 0)
        ahead = np.pad(step, pad_ahead, constant_values=np.nan)
        behind = np.pad(step, pad_behind, constant_values=np.nan)
        sizes.append(np.fmin(ahead, behind))        # NaN only when both are missing
    return np.maximum(sizes[0], sizes[1])           # NaN when either direction is


def texel_density(position, cascade, texel_world, mask, covered=None):
    """``TexelDensity`` over ``mask`` pixels: ``position`` (H, W, 3) world positions,
    ``cascade`` (H, W) CSM's cascade channel (fractional inside a blend band, where the
    texel size is interpolated between the two cascades; < 0 none), ``texel_world``
    scene units per texel for each cascade; ``covered`` the pixels with geometry, whose
    positions may serve as neighbours (default ``mask``)."""
    texel_world = np.asarray(texel_world, dtype=np.float64)
    covered = mask if covered is None else covered
    pixel = pixel_world_size(position, np.isfinite(position).all(axis=2) & covered)
    valid = mask & (cascade >= 0.0) & np.isfinite(pixel) & (pixel > 0.0)
    if texel_world.size == 0 or not valid.any():
        return TexelDensity(0, float("nan"), float("nan"), float("nan"), [], list(texel_world))
    c = np.clip(cascade[valid], 0.0, texel_world.size - 1)
    below = np.floor(c).astype(int)
    above = np.minimum(below + 1, texel_world.size - 1)
    texel = texel_world[below] + (texel_world[above] - texel_world[below]) * (c - below)
    footprint = texel / pixel[valid]
    p10, median, p90 = np.percentile(footprint, [10.0, 50.0, 90.0])
    share = np.bincount(np.rint(c).astype(int), minlength=texel_world.size) / c.size
    return TexelDensity(int(valid.sum()), float(median), float(p10), float(p90),
                        [float(s) for s in share], [float(t) for t in texel_world])


def ratio(csm_value, eevee_value):
    """CSM / EEVEE, None when either is missing or EEVEE's is 0."""
    if csm_value is None or eevee_value is None or eevee_value == 0:
        return None
    return csm_value / eevee_value


# ------------------------------------------------------------------------------ Blender

class _Changes:
    """Attribute changes on Blender data, undone in reverse order by ``restore()``."""

    def __init__(self):
        self._saved = []

    def set(self, owner, name, value):
        if not hasattr(owner, name):
            return
        self._saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, value)

    def restore(self):
        failed = []
        for owner, name, value in reversed(self._saved):
            try:
                setattr(owner, name, value)
            except (TypeError, ValueError, AttributeError):
                failed.append((owner, name, value))
        # Dependent enums (an EXR colour depth under a PNG format) need a second pass.
        for owner, name, value in failed:
            with contextlib.suppress(TypeError, ValueError, AttributeError):
                setattr(owner, name, value)
        self._saved = []


def eevee_engine_id():
    """4.2 .. 4.x call EEVEE Next 'BLENDER_EEVEE_NEXT'; 3.4 and 5.0 call it 'BLENDER_EEVEE'."""
    import bpy
    items = {item.identifier for item in
             bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"


def _sun_used_by_csm(scene):
    """The sun CSM shades with: the first sun among the render's object instances."""
    import bpy
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for instance in depsgraph.object_instances:
        obj = instance.object
        if obj.type == 'LIGHT' and obj.data.type == 'SUN':
            original = obj.original if obj.original else obj
            if not original.hide_render:
                return original
    return None


def _isolate_sun(scene, changes, sun_angle):
    """Hide every light but CSM's sun, set its angle (degrees) and black out the world,
    for every engine."""
    sun = _sun_used_by_csm(scene)
    if sun is None:
        raise CLIError("the scene has no sun (directional light): there is no sun shadow "
                       "to compare", EXIT_SCENE)
    for obj in scene.objects:
        if obj.type == 'LIGHT' and obj != sun:
            changes.set(obj, "hide_render", True)
    # Angle 0: a point-like sun, exact hard shadows; else the soft mode's disc.
    changes.set(sun.data, "angle", math.radians(sun_angle))
    changes.set(scene, "world", None)            # no ambient / world light in any engine
    changes.set(scene.csm, "debug_view", 'NONE')
    changes.set(scene.csm, "debug_inset", False)
    changes.set(scene.render, "film_transparent", False)
    changes.set(scene.render, "use_motion_blur", False)
    changes.set(scene.render, "resolution_percentage", 100)
    return sun


def _set_sun_shadow(sun, on):
    sun.data.use_shadow = on
    cycles_light = getattr(sun.data, "cycles", None)
    if cycles_light is not None and hasattr(cycles_light, "cast_shadow"):
        cycles_light.cast_shadow = on        # Blender < 4.0: Cycles' own switch


def _render_csm(scene):
    """CSM's combined RGB (H, W, 3), rows bottom-to-top, and its ``RenderResult`` (aux,
    normal and position images, the shadow plan, the wall time)."""
    from csm_engine.blender import engine
    scene.render.engine = "CSM"
    result = engine.render_final(scene, keep_images=True)
    if result.error:
        raise CLIError("CSM render failed: " + result.error, EXIT_RENDER)
    return result.images["combined"][..., :3].astype(np.float64), result


def _setup_exr_output(scene, changes):
    """Write the render as a 32-bit float EXR (scene-linear, no view transform)."""
    changes.set(scene.render, "use_compositing", False)
    changes.set(scene.render, "use_sequencer", False)
    image = scene.render.image_settings
    changes.set(image, "media_type", 'IMAGE')         # 5.0: the format list depends on it
    changes.set(image, "file_format", 'OPEN_EXR')
    changes.set(image, "color_depth", '32')
    changes.set(image, "color_mode", 'RGB')
    changes.set(scene.render, "use_file_extension", True)


def _setup_cycles(scene, changes, samples=1):
    cycles = scene.cycles
    for name, value in (("device", 'CPU'), ("samples", samples),
                        ("use_adaptive_sampling", False),
                        ("use_denoising", False), ("max_bounces", 0),
                        # Shadow rays pass through alpha-cut texels (leaves, grilles) as
                        # CSM's masked shadow pass does; 0 made them solid cards.
                        ("transparent_max_bounces", TRANSPARENT_BOUNCES),
                        # NOTE: a pixel centre needs a narrow Gaussian: Cycles' box filter
                        # is one pixel wide whatever its width says (default.json, 480x270,
                        # hard sun, 64 samples: 1,986 partly shadowed pixels with a box
                        # of width 0.01 or 1, 14 with a Gaussian of 0.01): a box would
                        # make the references sample the whole pixel.
                        ("pixel_filter_type", 'GAUSSIAN'),
                        ("filter_width", 0.01), ("seed", 0), ("use_animated_seed", False),
                        ("sample_clamp_direct", 0.0)):
        changes.set(cycles, name, value)
    _setup_exr_output(scene, changes)


def _setup_eevee(scene, changes, samples, soft):
    """EEVEE at its defaults but for what the comparison needs: ``samples`` render
    samples, pixel centres (a 0.01-pixel filter, as Cycles' narrow Gaussian and CSM's one sample),
    and on EEVEE Legacy (3.4) soft shadows only in soft mode."""
    changes.set(scene.eevee, "taa_render_samples", samples)
    changes.set(scene.render, "filter_size", 0.01)
    changes.set(scene.eevee, "use_soft_shadows", soft)
    _setup_exr_output(scene, changes)


def _render_exr(scene, changes, engine_id, path):
    """Render with ``engine_id`` and read the image back through a float EXR file:
    (RGB (H, W, 3) rows bottom-to-top, wall seconds)."""
    import bpy
    from csm_engine.blender import engine
    scene.render.engine = engine_id
    changes.set(scene.render, "filepath", path)
    start = time.perf_counter()
    engine.render_final(scene, write_still=True)
    seconds = time.perf_counter() - start
    if not os.path.isfile(path):
        raise CLIError(f"{engine_id} render finished but '{path}' was not written",
                       EXIT_RENDER)
    image = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * image.channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        rgb = pixels.reshape(height, width, image.channels)[..., :3].astype(np.float64)
    finally:
        bpy.data.images.remove(image)
    return rgb, seconds


@dataclasses.dataclass
class EngineVisibility:
    """One engine's sun visibility at one image size: ``vis`` (H, W) on / off, ``lit``
    (H, W) the pixels the sun lights with shadows off. CSM also has ``aux`` (its auxiliary
    target), ``normal`` and ``position`` (G-buffer world normal and position, H, W, 3) and
    ``texel_world`` (scene units per shadow texel, per cascade). ``seconds``: the
    shadows-on render (rendered second, so warm). Rows run bottom-to-top as GL and Blender
    store them."""
    vis: np.ndarray
    lit: np.ndarray
    aux: object = None
    seconds: float = 0.0
    normal: object = None
    position: object = None
    texel_world: tuple = ()
    samples: int = 1

    def flat_ground(self):
        """Pixels whose normal is within ``FLAT_GROUND_DEGREES`` of +Z (None without a
        G-buffer)."""
        if self.normal is None:
            return None
        return self.normal[..., 2] >= math.cos(math.radians(FLAT_GROUND_DEGREES))


@contextlib.contextmanager
def _isolated(scene, width, height, sun_angle=0.0):
    """The measurement set-up (only CSM's sun at ``sun_angle`` degrees, black world,
    ``width`` x ``height``); yields (sun, changes) and puts everything back afterwards."""
    changes = _Changes()
    engine_before = scene.render.engine
    try:
        sun = _isolate_sun(scene, changes, sun_angle)
        changes.set(sun.data, "use_shadow", sun.data.use_shadow)
        cycles_light = getattr(sun.data, "cycles", None)
        if cycles_light is not None and hasattr(cycles_light, "cast_shadow"):
            changes.set(cycles_light, "cast_shadow", cycles_light.cast_shadow)
        changes.set(scene.render, "resolution_x", width)
        changes.set(scene.render, "resolution_y", height)
        # Pixel centres, as Cycles' 0.01-pixel Gaussian filter sees them: no anti-aliasing.
        changes.set(scene.csm, "render_samples", 1)
        changes.set(scene.csm, "fxaa", False)
        yield sun, changes
    finally:
        changes.restore()
        scene.render.engine = engine_before


def csm_visibility(scene, width, height, sun_angle=0.0, shadow_filter=None):
    """Render CSM twice (sun shadows off, then on) with the scene's current CSM settings;
    ``shadow_filter`` sets ``scene.csm.shadow_filter`` for the measurement when CSM has
    that setting (None: keep it)."""
    with _isolated(scene, width, height, sun_angle) as (sun, changes):
        if shadow_filter is not None and hasattr(scene.csm, "shadow_filter"):
            changes.set(scene.csm, "shadow_filter", shadow_filter)
        _set_sun_shadow(sun, False)
        csm_off, _ = _render_csm(scene)
        _set_sun_shadow(sun, True)
        csm_on, result = _render_csm(scene)
    off_sum = csm_off.sum(axis=2)
    images, plan = result.images, result.plan
    aux = images["aux"].astype(np.float64)
    count = plan.cascade_count if plan is not None else 0
    # CSM's coverage channel is 0 on the background, whatever the colour says.
    return EngineVisibility(
        vis=visibility_from_on_off(csm_on.sum(axis=2), off_sum),
        lit=lit_mask(off_sum) & (aux[..., 3] > 0.5), aux=aux,
        seconds=result.timings.get("wall", 0.0),
        normal=images["normal"][..., :3].astype(np.float64),
        position=images["position"][..., :3].astype(np.float64),
        texel_world=tuple(float(t.texel_world) for t in plan.tiles[:count]) if count else ())


def _reference_visibility(scene, width, height, sun_angle, engine_id, setup, samples):
    with _isolated(scene, width, height, sun_angle) as (sun, changes):
        setup(changes)
        with tempfile.TemporaryDirectory(prefix="csm_ground_truth_") as folder:
            # Off first: EEVEE compiles its shaders in its first render of a session.
            _set_sun_shadow(sun, False)
            off, _ = _render_exr(scene, changes, engine_id, os.path.join(folder, "off.exr"))
            _set_sun_shadow(sun, True)
            on, seconds = _render_exr(scene, changes, engine_id,
                                      os.path.join(folder, "on.exr"))
    off_sum = off.sum(axis=2)
    return EngineVisibility(vis=visibility_from_on_off(on.sum(axis=2), off_sum),
                            lit=lit_mask(off_sum), seconds=seconds, samples=samples)


def cycles_visibility(scene, width, height, sun_angle=0.0, samples=None):
    """The reference: render Cycles twice (sun shadows off, on). It does not depend on any
    CSM setting, so one reference serves every CSM setting on the same scene and size.
    ``samples`` None: 1 in hard mode, ``SOFT_CYCLES_SAMPLES`` in soft mode."""
    if samples is None:
        samples = SOFT_CYCLES_SAMPLES if sun_angle > 0.0 else 1
    return _reference_visibility(
        scene, width, height, sun_angle, "CYCLES",
        lambda changes: _setup_cycles(scene, changes, samples), samples)


def _setup_cycles_whole_pixel(scene, changes, samples):
    _setup_cycles(scene, changes, samples)
    changes.set(scene.cycles, "pixel_filter_type", 'BOX')   # samples over the whole pixel
    changes.set(scene.cycles, "filter_width", 1.0)


def cycles_whole_pixel_lit(scene, width, height, samples=WHOLE_PIXEL_SAMPLES):
    """Hard mode's second reference: the pixels whose whole area the sun lights with no
    shadow on it (H, W bool, rows bottom-to-top). Cycles renders the sun shadows off and
    on again with ``samples`` samples spread over each pixel's square (a 1-pixel box
    filter); a pixel is whole-lit when on / off >= ``FULLY_LIT``."""
    whole = _reference_visibility(
        scene, width, height, 0.0, "CYCLES",
        lambda changes: _setup_cycles_whole_pixel(scene, changes, samples), samples)
    return whole.lit & (whole.vis >= FULLY_LIT)


def eevee_visibility(scene, width, height, sun_angle=0.0, samples=None):
    """EEVEE rendered twice (sun shadows off, on), with soft shadows in soft mode.
    ``samples`` None: 1 in hard mode, ``SOFT_EEVEE_SAMPLES`` in soft mode."""
    soft = sun_angle > 0.0
    if samples is None:
        samples = SOFT_EEVEE_SAMPLES if soft else 1
    return _reference_visibility(
        scene, width, height, sun_angle, eevee_engine_id(),
        lambda changes: _setup_eevee(scene, changes, samples, soft), samples)


def compare_engines(csm, cycles, also_lit=None, flat=None, engine="CSM", whole_lit=None):
    """Compare one engine's ``EngineVisibility`` (CSM's or EEVEE's) with Cycles'; returns
    (Comparison, class image with rows bottom-to-top). With an ``aux`` target (CSM) it
    includes the aux cross-check; ``flat`` defaults to the engine's own flat ground;
    ``whole_lit``: ``cycles_whole_pixel_lit``'s mask, or None."""
    if flat is None:
        flat = csm.flat_ground()
    result, classes = compare(csm.vis, cycles.vis, csm.lit, cycles.lit, also_lit, flat,
                              whole_lit)
    result.engine = engine
    result.seconds = csm.seconds
    if csm.aux is not None:
        compared = classes != 0
        compared &= classes != 5
        aux_vis = csm.aux[..., 0]
        result.aux_classified_differently = int(
            ((aux_vis < SHADOWED_BELOW) != (csm.vis < SHADOWED_BELOW))[compared].sum())
        result.aux_max_difference = float(np.abs(aux_vis - csm.vis)[compared].max()) \
            if compared.any() else 0.0
    return result, classes


@dataclasses.dataclass
class Report:
    """One run: CSM and (unless skipped) EEVEE against the same Cycles reference."""
    sun_angle: float
    csm: Comparison
    eevee: object                  # Comparison or None
    texel: TexelDensity
    cycles_samples: int
    eevee_samples: int
    eevee_engine: str
    cycles_seconds: float
    cycles_noise: float            # mean binomial bound sqrt(v(1-v)/N) on compared pixels
    csm_shadow_filter: str = None  # what soft mode set, None when untouched

    @property
    def mode(self):
        return "soft" if self.sun_angle > 0.0 else "hard"

    def ratios(self):
        """CSM / EEVEE for the headline numbers (None where undefined)."""
        if self.eevee is None:
            return {}
        names = ("mismatch_percent", "false_shadow_percent", "missed_shadow_percent",
                 "mean_abs_error", "partial_on_lit_percent", "seconds")
        values = {n: ratio(getattr(self.csm, n), getattr(self.eevee, n)) for n in names}
        csm_width, eevee_width = (None if c.penumbra_width_error_percent is None else
                                  abs(c.penumbra_width_error_percent)
                                  for c in (self.csm, self.eevee))
        values["penumbra_width_error"] = ratio(csm_width, eevee_width)
        return values

    def as_dict(self):
        values = self.csm.as_dict()        # CSM's numbers at the top level, as before
        values.update(
            mode=self.mode, sun_angle_deg=self.sun_angle, csm=self.csm.as_dict(),
            eevee=self.eevee.as_dict() if self.eevee is not None else None,
            csm_over_eevee=self.ratios(), texel_density=self.texel.as_dict(),
            cycles_samples=self.cycles_samples, eevee_samples=self.eevee_samples,
            eevee_engine=self.eevee_engine, cycles_seconds=self.cycles_seconds,
            cycles_noise=self.cycles_noise, csm_shadow_filter=self.csm_shadow_filter)
        return values

    def summary(self):
        lines = [self.csm.summary()]
        engines = [self.csm] + ([self.eevee] if self.eevee is not None else [])
        ratios = self.ratios()

        def row(label, values, key=None, digits=3):
            cells = ["-" if v is None else f"{v:.{digits}f}" for v in values]
            if self.eevee is not None:
                r = ratios.get(key)
                cells.append("-" if r is None else f"{r:.2f}")
            return f"{label:<34}" + "".join(f"{c:>12}" for c in cells)

        header = f"{'':<34}" + "".join(f"{e.engine:>12}" for e in engines)
        if self.eevee is not None:
            header += f"{'CSM/EEVEE':>12}"
        lines += ["", f"{self.mode} shadows, sun angle {self.sun_angle:g} deg; Cycles "
                      f"{self.cycles_samples} samples (noise <= {self.cycles_noise:.4f})"
                      + (f", {self.eevee_engine} {self.eevee_samples} samples"
                         if self.eevee is not None else ""), header]
        lines.append(row("mismatch %", [e.mismatch_percent for e in engines],
                         "mismatch_percent"))
        lines.append(row("false shadow %", [e.false_shadow_percent for e in engines],
                         "false_shadow_percent"))
        lines.append(row("missed shadow %", [e.missed_shadow_percent for e in engines],
                         "missed_shadow_percent"))
        lines.append(row("mean abs visibility error", [e.mean_abs_error for e in engines],
                         "mean_abs_error", 4))
        lines.append(row("mean signed visibility error",
                         [e.mean_signed_error for e in engines], None, 4))
        lines.append(row("penumbra width error %",
                         [e.penumbra_width_error_percent for e in engines],
                         "penumbra_width_error", 1))
        lines.append(row("partial shadow on fully lit %",
                         [e.partial_on_lit_percent for e in engines],
                         "partial_on_lit_percent"))
        lines.append(row("flat lit ground at >= 0.999",
                         [e.flat_ground_full_fraction for e in engines], None, 4))
        lines.append(row("  whole pixel lit in Cycles",
                         [e.flat_ground_whole_pixel_full_fraction for e in engines],
                         None, 4))
        lines.append(row("  of the rest, next to a shadow",
                         [e.flat_ground_short_at_edge_fraction for e in engines], None, 3))
        lines.append(row("  not counting the pixel next to a shadow",
                         [e.flat_ground_away_from_edges_full_fraction for e in engines],
                         None, 4))
        lines.append(row("frame s (shadows on, warm)", [e.seconds for e in engines],
                         "seconds"))
        t = self.texel
        lines.append(f"CSM texel footprint (pixels per shadow texel): median "
                     f"{t.median_footprint_px:.2f}, p10 {t.p10_footprint_px:.2f}, p90 "
                     f"{t.p90_footprint_px:.2f} over {t.pixels} pixels; cascade share "
                     + " / ".join(f"{100 * s:.0f} %" for s in t.cascade_share))
        return "\n".join(lines)


def measure_report(scene, width, height, sun_angle=0.0, eevee=True, cycles_samples=None,
                   eevee_samples=None, csm_shadow_filter="auto", heatmap_path=None):
    """Render ``scene`` with CSM, EEVEE (unless ``eevee`` is False) and Cycles, shadows
    on and off, and compare each with Cycles. Returns a ``Report``.

    ``csm_shadow_filter``: "auto" sets CSM's ``shadow_filter`` to 'SOFT' in soft mode
    (when CSM has the setting), None keeps the scene's, any other value is used as is.
    ``heatmap_path``: CSM's heat map (PNG); EEVEE's goes beside it as ``<stem>_eevee.png``.
    Hard mode paints classes, soft mode the signed visibility error. The scene is left as
    it was found."""
    soft = sun_angle > 0.0
    if csm_shadow_filter == "auto":
        csm_shadow_filter = 'SOFT' if soft and hasattr(scene.csm, "shadow_filter") else None
    csm = csm_visibility(scene, width, height, sun_angle, csm_shadow_filter)
    other = eevee_visibility(scene, width, height, sun_angle, eevee_samples) if eevee \
        else None
    cycles = cycles_visibility(scene, width, height, sun_angle, cycles_samples)
    # Hard mode: which flat lit pixels no shadow edge crosses (soft mode has penumbrae,
    # whose pixels are not fully lit anyway).
    whole_lit = None if soft else cycles_whole_pixel_lit(scene, width, height)
    flat = csm.flat_ground()        # the G-buffer's geometry is every engine's geometry
    csm_result, csm_classes = compare_engines(
        csm, cycles, other.lit if other is not None else None, flat, "CSM", whole_lit)
    eevee_result = eevee_classes = None
    if other is not None:
        eevee_result, eevee_classes = compare_engines(other, cycles, csm.lit, flat, "EEVEE",
                                                      whole_lit)
    compared = (csm_classes != 0) & (csm_classes != 5)
    texel = texel_density(csm.position, csm.aux[..., 1], csm.texel_world, compared,
                          csm.aux[..., 3] > 0.5)
    v = cycles.vis[compared]
    noise = float(np.sqrt(v * (1.0 - v) / cycles.samples).mean()) if v.size else 0.0
    if heatmap_path:
        for engine_vis, classes, path in (
                (csm, csm_classes, heatmap_path),
                (other, eevee_classes, eevee_heatmap_path(heatmap_path))):
            if engine_vis is None:
                continue
            image = signed_error_heatmap(engine_vis.vis, cycles.vis, classes) if soft \
                else heatmap(classes)
            write_png(path, image[::-1])        # PNG rows run top to bottom
    return Report(sun_angle=sun_angle, csm=csm_result, eevee=eevee_result, texel=texel,
                  cycles_samples=cycles.samples,
                  eevee_samples=other.samples if other is not None else 0,
                  eevee_engine=eevee_engine_id() if other is not None else "",
                  cycles_seconds=cycles.seconds, cycles_noise=noise,
                  csm_shadow_filter=csm_shadow_filter)


def measure(scene, width, height, heatmap_path=None, sun_angle=0.0):
    """CSM against Cycles only (four renders); returns CSM's ``Comparison`` and writes the
    heat map (PNG) when ``heatmap_path`` is given. The scene is left as it was found. To
    compare many CSM settings on one scene, call ``cycles_visibility`` once and
    ``csm_visibility`` + ``compare_engines`` per setting (``quality_report.py`` does)."""
    return measure_report(scene, width, height, sun_angle, eevee=False,
                          heatmap_path=heatmap_path).csm


def eevee_heatmap_path(path):
    stem, extension = os.path.splitext(path)
    return f"{stem}_eevee{extension or '.png'}"


# --------------------------------------------------------------------- built-in scenes

BUNDLED_SCENES = ("shadow_test", "default", "point_lights")
BUILT_SCENES = ("terrain", "monastery")
ALL_SCENES = BUNDLED_SCENES + BUILT_SCENES


def build_terrain_scene(width, height):
    """A scene not made from the project's files: a 200 m grid displaced by Blender's
    Clouds texture (plain operators and a Displace modifier), a sun 10 degrees above the
    horizon, a camera looking across the hills. Long, grazing shadows over curved ground:
    the hard case for shadow maps."""
    import bpy
    scene = open_scene()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=200, y_subdivisions=200, size=200.0)
    terrain = bpy.context.object
    terrain.name = "terrain"
    texture = bpy.data.textures.new("terrain_hills", 'CLOUDS')
    texture.noise_scale = 40.0        # hills some 40 m across
    texture.noise_depth = 3
    displace = terrain.modifiers.new("hills", 'DISPLACE')
    displace.texture = texture
    displace.texture_coords = 'LOCAL'
    displace.strength = 24.0
    displace.mid_level = 0.5
    material = bpy.data.materials.new("terrain")
    material.diffuse_color = (0.45, 0.5, 0.35, 1.0)
    terrain.data.materials.append(material)
    # Sun 10 degrees up, from the right and a little behind the camera's right shoulder.
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(80.0), 0.0,
                                                   math.radians(65.0)))
    bpy.context.object.data.energy = 3.0
    bpy.ops.object.camera_add(location=(0.0, -95.0, 30.0),
                              rotation=(math.radians(72.0), 0.0, 0.0))
    camera = bpy.context.object
    camera.data.lens = 30.0
    camera.data.clip_start = 0.5
    camera.data.clip_end = 300.0
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = width, height
    return scene


def open_named_scene(name, overrides, resolution):
    """A scene by file path, bundled name (``default``), or built name (``terrain``,
    ``monastery``), with ``--set`` overrides applied; returns (scene, label)."""
    from csm_engine.core import paths
    if name is None:
        name = paths.default_scene_path()
    folder = os.path.dirname(paths.default_scene_path())
    if not os.path.exists(name) and name in BUNDLED_SCENES:
        name = os.path.join(folder, name + ".json")
    if name in BUILT_SCENES and not os.path.exists(name):
        if name == "terrain":
            scene = build_terrain_scene(*resolution)
        else:
            from . import bench_models
            try:
                scene = bench_models.build_monastery_scene(
                    width=resolution[0], height=resolution[1], log=lambda *_: None)
            except bench_models.ModelUnavailable as error:
                raise CLIError(f"monastery: {error}", EXIT_SCENE)
        for override in overrides:
            apply_override(scene.csm, override)
        scene.render.resolution_percentage = 100
        return scene, name
    return open_scene(name, overrides, resolution), name


# ------------------------------------------------------------------------ command line

def build_parser(prog=PROG):
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Compare CSM's and EEVEE's sun shadows with Cycles' ray-traced shadows "
                    "on a scene: hard (sun angle 0) or soft (--sun-angle); mismatch, false "
                    "and missed shadow, mean visibility error, penumbra width, partial "
                    "shadow on lit pixels, flat ground, CSM's texel density.")
    parser.add_argument("scene", nargs="?",
                        help="scene .json, or a name: " + ", ".join(ALL_SCENES) +
                             " (default: the bundled default scene)")
    parser.add_argument("--resolution", metavar="WxH",
                        help=f"image size in pixels (default {DEFAULT_RESOLUTION}; with "
                             f"--all, hard mode's)")
    parser.add_argument("--sun-angle", type=float, default=0.0, metavar="DEG",
                        help="the sun's Angle in degrees for every engine; 0 (default) is "
                             "hard mode, above 0 soft mode")
    parser.add_argument("--cycles-samples", type=int, metavar="N",
                        help=f"Cycles' samples (default 1 hard, {SOFT_CYCLES_SAMPLES} soft)")
    parser.add_argument("--eevee-samples", type=int, metavar="N",
                        help=f"EEVEE's render samples (default 1 hard, {SOFT_EEVEE_SAMPLES} "
                             "soft)")
    parser.add_argument("--no-eevee", action="store_true",
                        help="compare CSM only (half the renders)")
    parser.add_argument("--heatmap", metavar="PNG",
                        help="write CSM's heat map, and EEVEE's as <stem>_eevee.png. Hard: "
                             "grey = agree (light lit, dark shadowed), red = false shadow, "
                             "blue = missed shadow, yellow = lit by one engine only, black = "
                             "not compared. Soft: Cycles' visibility in grey, red where the "
                             "engine is darker, blue where lighter (full at 0.5)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="SETTING=VALUE",
                        help="override a CSM setting, e.g. --set depth_bias=0 (repeatable)")
    parser.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    parser.add_argument("--max-mismatch", type=float, metavar="PERCENT",
                        help="exit with code 1 when CSM's mismatch exceeds PERCENT")
    suite = parser.add_argument_group("the documented suite")
    suite.add_argument("--all", action="store_true",
                       help="every scene in hard mode and soft mode at each --sun-angles; "
                            "heat maps into --out-dir/images, tables into "
                            "--out-dir/ground-truth.md")
    suite.add_argument("--scenes", nargs="+", default=list(ALL_SCENES), metavar="SCENE",
                       help="with --all: the scenes (default: " + " ".join(ALL_SCENES) + ")")
    suite.add_argument("--sun-angles", nargs="*", type=float, default=list(ALL_SUN_ANGLES),
                       metavar="DEG", help="with --all: soft-mode angles (default 1 3 10)")
    suite.add_argument("--soft-resolution", default=SOFT_RESOLUTION, metavar="WxH",
                       help=f"with --all: soft mode's image size (default {SOFT_RESOLUTION})")
    suite.add_argument("--out-dir", metavar="DIR", default="docs",
                       help="with --all: where ground-truth.md and images/ are (default docs)")
    return parser


def _check_output_folders(args):
    for label, path in (("--heatmap", args.heatmap), ("--json", args.json)):
        if path:
            folder = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(folder):
                raise CLIError(f"{label}: cannot write '{path}': folder '{folder}' "
                               "does not exist")


def _check_cycles(scene):
    if not hasattr(scene, "cycles"):
        raise CLIError("Cycles is not available in this Blender: enable the Cycles add-on",
                       EXIT_RENDER)


def _user_sets(overrides, name):
    return any(text.split("=", 1)[0].strip() == name for text in overrides)


def run(argv, prog=PROG):
    args = build_parser(prog).parse_args(argv)
    if args.sun_angle < 0.0 or args.sun_angle >= 180.0:
        raise CLIError(f"--sun-angle: {args.sun_angle:g} is not in 0 .. 180 degrees")
    for label, value in (("--cycles-samples", args.cycles_samples),
                         ("--eevee-samples", args.eevee_samples)):
        if value is not None and value < 1:
            raise CLIError(f"{label}: {value} is not a positive number of samples")
    _check_output_folders(args)
    if args.all:
        return run_all(args, argv, prog)
    width, height = parse_resolution(args.resolution or DEFAULT_RESOLUTION)
    scene, scene_path = open_named_scene(args.scene, args.overrides, (width, height))
    _check_cycles(scene)
    shadow_filter = None if _user_sets(args.overrides, "shadow_filter") else "auto"
    report = measure_report(scene, width, height, args.sun_angle, not args.no_eevee,
                            args.cycles_samples, args.eevee_samples, shadow_filter,
                            args.heatmap)
    settings = ", ".join(args.overrides) if args.overrides else "defaults"
    if report.csm_shadow_filter:
        settings += f" (soft mode: shadow_filter={report.csm_shadow_filter})"
    print(f"ground truth: {scene_path} at {width}x{height}, CSM settings: {settings}")
    print(report.summary())
    if args.heatmap:
        print(f"heat map: {os.path.abspath(args.heatmap)}"
              + (f" (EEVEE: {os.path.abspath(eevee_heatmap_path(args.heatmap))})"
                 if not args.no_eevee else ""))
    if args.json:
        values = report.as_dict()
        values.update(scene=os.path.abspath(scene_path) if os.path.exists(scene_path)
                      else scene_path, overrides=list(args.overrides),
                      resolution=f"{width}x{height}")
        with open(args.json, "w", encoding="utf-8") as stream:
            json.dump(values, stream, indent=2)
    if args.max_mismatch is not None and report.csm.mismatch_percent > args.max_mismatch:
        print(f"ground truth: mismatch {report.csm.mismatch_percent:.3f} % exceeds "
              f"{args.max_mismatch:g} %", file=sys.stderr)
        return 1
    return 0


# ------------------------------------------------------------------------ --all suite

def run_all(args, argv, prog):
    """The documented suite: each scene in hard mode at --resolution and in soft mode at
    each angle at --soft-resolution; heat maps, the JSON and the generated tables."""
    hard_size = parse_resolution(args.resolution or DEFAULT_RESOLUTION)
    soft_size = parse_resolution(args.soft_resolution)
    images = os.path.join(args.out_dir, "images")
    markdown = os.path.join(args.out_dir, "ground-truth.md")
    if not os.path.isdir(images):
        raise CLIError(f"--out-dir: '{images}' does not exist")
    report_io.read_page(markdown, BEGIN, END, title="Ground truth")   # refuse early
    shadow_filter = None if _user_sets(args.overrides, "shadow_filter") else "auto"
    started = time.monotonic()
    runs, skipped = [], {}
    # Angle by angle (hard mode on every scene first): a suite stopped half-way has
    # whole tables rather than one scene in every mode.
    for angle in [0.0] + list(args.sun_angles):
        for name in args.scenes:
            if name in skipped:
                continue
            size = soft_size if angle > 0.0 else hard_size
            t0 = time.monotonic()
            try:
                scene, _ = open_named_scene(name, args.overrides, size)
            except CLIError as error:
                if name not in BUILT_SCENES:
                    raise
                skipped[name] = str(error)
                print(f"[ground truth] {name}: skipped ({error})", flush=True)
                continue
            _check_cycles(scene)
            label = "hard" if angle == 0.0 else f"soft{angle:g}"
            heat = os.path.join(images, f"ground_truth_{os.path.basename(name)}_{label}.png")
            report = measure_report(scene, size[0], size[1], angle,
                                    heatmap_path=heat, csm_shadow_filter=shadow_filter)
            values = report.as_dict()
            values.update(scene=name, resolution=f"{size[0]}x{size[1]}",
                          heatmap=os.path.relpath(heat, args.out_dir),
                          run_seconds=time.monotonic() - t0)
            runs.append(values)
            _write_suite(args, argv, prog, markdown, started, skipped, runs)
            c, e = report.csm, report.eevee
            print(f"[ground truth {len(runs)}] {name} {label} {size[0]}x{size[1]}: mismatch "
                  f"CSM {c.mismatch_percent:.3f} % EEVEE {e.mismatch_percent:.3f} %, mean "
                  f"abs error CSM {c.mean_abs_error:.4f} EEVEE {e.mean_abs_error:.4f} "
                  f"({time.monotonic() - t0:.0f} s)", flush=True)
    _write_suite(args, argv, prog, markdown, started, skipped, runs)
    print(f"[ground truth] {len(runs)} runs in {time.monotonic() - started:.0f} s; tables "
          f"in {os.path.abspath(markdown)}", flush=True)
    return 0


def _write_suite(args, argv, prog, markdown, started, skipped, runs):
    """The tables and the JSON so far (after every run, so a long suite stopped half-way
    still leaves its numbers)."""
    report = report_io.run_facts(prog, argv, runtime_s=time.monotonic() - started,
                                 overrides=list(args.overrides), skipped=skipped,
                                 runs=runs)
    report_io.write_section(markdown, BEGIN, END, build_markdown(report),
                            title="Ground truth")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as stream:
            json.dump(report, stream, indent=2)


def _f(value, digits=3, suffix=""):
    return "-" if value is None else f"{value:.{digits}f}{suffix}"


def _trio(run, key, digits=3):
    """'CSM / EEVEE / ratio' for one number of a run dict."""
    c, e = run["csm"].get(key), run["eevee"].get(key)
    return f"{_f(c, digits)} | {_f(e, digits)} | {_f(ratio(c, e), 2)}"


def build_markdown(report):
    """The generated tables of docs/ground-truth.md from an ``--all`` report dict."""
    runs = report["runs"]
    out = [f"Generated by `{report['command']}` on {report['date']}: Blender "
           f"{report['blender']}, {report['machine']}; {len(runs)} runs in "
           f"{report['runtime_s'] / 60:.0f} min. CSM settings: "
           f"{', '.join(report['overrides']) or 'defaults'}.", ""]
    for name, reason in report["skipped"].items():
        out += [f"Skipped {name}: {reason}", ""]
    hard = [r for r in runs if r["mode"] == "hard"]
    soft = [r for r in runs if r["mode"] == "soft"]
    if hard:
        first = hard[0]
        out += ["### Hard shadows (sun angle 0)", "",
                f"Cycles {first['cycles_samples']} sample, EEVEE ({first['eevee_engine']}) "
                f"{first['eevee_samples']} sample. Each cell: CSM | EEVEE | CSM/EEVEE.", "",
                "| scene | size | compared px | mismatch % CSM | EEVEE | CSM/EEVEE "
                "| false shadow % CSM | EEVEE | CSM/EEVEE | missed shadow % CSM | EEVEE "
                "| CSM/EEVEE | partial shadow on fully lit % CSM | EEVEE | CSM/EEVEE "
                "| flat lit ground >= 0.999 (centre lit) CSM / EEVEE | ... whole pixel "
                "lit CSM / EEVEE |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in hard:
            out.append(
                f"| {os.path.basename(r['scene'])} | {r['resolution']} | "
                f"{r['csm']['compared_pixels']} | {_trio(r, 'mismatch_percent')} | "
                f"{_trio(r, 'false_shadow_percent')} | {_trio(r, 'missed_shadow_percent')} "
                f"| {_trio(r, 'partial_on_lit_percent')} | "
                f"{_f(r['csm']['flat_ground_full_fraction'], 4)} / "
                f"{_f(r['eevee']['flat_ground_full_fraction'], 4)} | "
                f"{_f(r['csm'].get('flat_ground_whole_pixel_full_fraction'), 4)} / "
                f"{_f(r['eevee'].get('flat_ground_whole_pixel_full_fraction'), 4)} |")
        out.append("")
    if soft:
        first = soft[0]
        out += ["### Soft shadows", "",
                f"Cycles {first['cycles_samples']} samples, EEVEE ({first['eevee_engine']}) "
                f"{first['eevee_samples']} samples; CSM shadow_filter: "
                f"{first['csm_shadow_filter'] or 'unchanged (the setting does not exist)'}. "
                "Each trio: CSM | EEVEE | CSM/EEVEE. Penumbra width error: penumbra pixels "
                "(0.05 < visibility < 0.95) relative to Cycles', minus 1 (0 is right, "
                "negative too sharp); its ratio compares the absolute values.", "",
                "| scene | sun angle | size | mean abs visibility error CSM | EEVEE "
                "| CSM/EEVEE | penumbra width error % CSM | EEVEE | CSM/EEVEE | partial "
                "shadow on fully lit % CSM | EEVEE | CSM/EEVEE | mismatch % CSM | EEVEE "
                "| CSM/EEVEE | Cycles noise bound |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in soft:
            widths = (r["csm"]["penumbra_width_error_percent"],
                      r["eevee"]["penumbra_width_error_percent"])
            width_ratio = r["csm_over_eevee"].get("penumbra_width_error")
            out.append(
                f"| {os.path.basename(r['scene'])} | {r['sun_angle_deg']:g} | "
                f"{r['resolution']} | {_trio(r, 'mean_abs_error', 4)} | "
                f"{_f(widths[0], 1)} | {_f(widths[1], 1)} | {_f(width_ratio, 2)} | "
                f"{_trio(r, 'partial_on_lit_percent')} | {_trio(r, 'mismatch_percent')} | "
                f"{r['cycles_noise']:.4f} |")
        out.append("")
    if runs:
        out += ["### Frame time and CSM's texel density", "",
                "Frame: the shadows-on render, warm, wall clock (seconds, 1 CSM sample). "
                "Texel footprint: screen pixels one shadow texel of the pixel's cascade "
                "spans (lower is sharper), over the compared pixels.", "",
                "| scene | mode | size | CSM s | EEVEE s | Cycles s | texel footprint "
                "median | p10 | p90 | pixels per cascade |",
                "|---|---|---|---|---|---|---|---|---|---|"]
        for r in runs:
            t = r["texel_density"]
            out.append(
                f"| {os.path.basename(r['scene'])} | {r['mode']} "
                f"{'' if r['mode'] == 'hard' else format(r['sun_angle_deg'], 'g') + ' deg'}"
                f" | {r['resolution']} | {r['csm']['seconds']:.2f} | "
                f"{r['eevee']['seconds']:.2f} | {r['cycles_seconds']:.1f} | "
                f"{_f(t['median_footprint_px'], 2)} | {_f(t['p10_footprint_px'], 2)} | "
                f"{_f(t['p90_footprint_px'], 2)} | "
                + " / ".join(f"{100 * s:.0f} %" for s in t["cascade_share"]) + " |")
        out.append("")
    return "\n".join(out) + "\n"


def main(argv=None, prog=PROG):
    return run_reporting_errors(run, argv, prog, "ground truth")


if __name__ == "__main__":
    from csm_engine.blender.compat import exit_process
    exit_process(main())
