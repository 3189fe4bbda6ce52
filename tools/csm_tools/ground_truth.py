"""Ground truth for CSM's sun shadows: the same scene, ray traced by Cycles, pixel by pixel.

Owns the comparison tool ``./dev ground-truth scene.json`` (``python -m
csm_tools.ground_truth``). It renders the
scene with CSM and with Cycles on the CPU, each twice: once with the sun's shadows on and
once with them off. Sun visibility is the ratio on / off per pixel, so intensity, BRDF and
colour differences between the engines cancel and only the shadow test remains
(docs/ground-truth.md). Cycles is set up to
give exact hard shadows: sun angle 0, 1 sample, no bounces, a box pixel filter of width 0.01
(one ray through the pixel centre, where CSM's rasterizer also samples), black world.

CSM also writes its sun visibility into the auxiliary target (``aux[..., 0]``); the tool
compares that channel with CSM's own on/off ratio on every compared pixel and reports how
far they differ, which proves the ratio method measures what the shader computes.

A pixel is compared when both engines light it with shadows off (``off`` above a small
fraction of the image's typical brightness): background, surfaces facing away from the sun
and grazing surfaces are excluded. It counts as shadowed when visibility < 0.5.
Every light but the sun CSM shades with (the first sun; point, spot, area lights and
further suns) is hidden, the sun's angle is 0 and the world is black for both engines; the
scene's camera and CSM settings are kept (debug views are switched off for the
measurement). Everything the tool changes on the scene is restored afterwards.

The statistics and the heat map are plain numpy (PNGs through ``report_io``); Blender is
imported only inside the functions that render.
"""

import argparse
import contextlib
import dataclasses
import json
import os
import sys
import tempfile

import numpy as np

from csm_engine.blender.cli import (CLIError, EXIT_RENDER, EXIT_SCENE, open_scene,
                                    parse_resolution, run_reporting_errors)

from .report_io import write_png

SHADOWED_BELOW = 0.5            # visibility under this counts as "in shadow"
LIT_FRACTION = 1e-3             # compared when off > this x the 99th percentile of off
DEFAULT_RESOLUTION = "1280x720"
TRANSPARENT_BOUNCES = 64        # alpha-cut layers a Cycles shadow ray may pass through
PROG = "./dev ground-truth"

# Heat-map colours (sRGB bytes).
COLOR_EXCLUDED = (0, 0, 0)          # background, unlit, facing away from the sun
COLOR_AGREE_LIT = (200, 200, 200)
COLOR_AGREE_SHADOW = (90, 90, 90)
COLOR_FALSE_SHADOW = (230, 30, 30)  # CSM shadowed, Cycles lit: acne, overlapping casters
COLOR_MISSED_SHADOW = (40, 90, 255)  # CSM lit, Cycles shadowed: peter-panning, clipping
COLOR_LIT_BY_ONE = (200, 170, 0)    # only one engine lights the pixel: silhouettes, normals


@dataclasses.dataclass
class Comparison:
    """What the tool reports. Percentages are of the compared pixels."""
    width: int
    height: int
    compared_pixels: int
    false_shadow_pixels: int
    missed_shadow_pixels: int
    lit_by_one_pixels: int         # lit (shadows off) in one engine only; not compared
    cycles_shadowed_pixels: int
    csm_shadowed_pixels: int
    # CSM's aux visibility channel against CSM's own on/off ratio, on compared pixels.
    aux_classified_differently: int = 0
    aux_max_difference: float = 0.0

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

    def as_dict(self):
        values = dataclasses.asdict(self)
        values.update(mismatch_percent=self.mismatch_percent,
                      false_shadow_percent=self.false_shadow_percent,
                      missed_shadow_percent=self.missed_shadow_percent,
                      shadow_lost_percent=self.shadow_lost_percent)
        return values

    def summary(self):
        total = self.width * self.height
        return "\n".join([
            f"compared pixels: {self.compared_pixels} of {total} "
            f"({100.0 * self.compared_pixels / max(total, 1):.1f} %); "
            f"shadowed: Cycles {self.cycles_shadowed_pixels}, CSM {self.csm_shadowed_pixels}",
            f"mismatch: {self.mismatch_percent:.3f} %  (false shadow "
            f"{self.false_shadow_percent:.3f} %, missed shadow "
            f"{self.missed_shadow_percent:.3f} %)",
            f"of Cycles' shadowed pixels, CSM shows lit: {self.shadow_lost_percent:.1f} %",
            f"lit by one engine only (not compared): {self.lit_by_one_pixels} pixels",
            f"CSM aux visibility vs CSM on/off ratio: {self.aux_classified_differently} "
            f"pixels classified differently, max difference {self.aux_max_difference:.2g}",
        ])


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


def compare(csm_vis, cycles_vis, csm_lit, cycles_lit):
    """Classify every pixel; returns (Comparison, class image). Classes: 0 excluded,
    1 agree lit, 2 agree shadowed, 3 false shadow, 4 missed shadow, 5 lit by one only."""
    compared = csm_lit & cycles_lit
    csm_dark = csm_vis < SHADOWED_BELOW
    cycles_dark = cycles_vis < SHADOWED_BELOW
    classes = np.zeros(csm_vis.shape, dtype=np.uint8)
    classes[csm_lit ^ cycles_lit] = 5
    classes[compared & ~csm_dark & ~cycles_dark] = 1
    classes[compared & csm_dark & cycles_dark] = 2
    classes[compared & csm_dark & ~cycles_dark] = 3
    classes[compared & ~csm_dark & cycles_dark] = 4
    height, width = csm_vis.shape
    result = Comparison(
        width=width, height=height, compared_pixels=int(compared.sum()),
        false_shadow_pixels=int((classes == 3).sum()),
        missed_shadow_pixels=int((classes == 4).sum()),
        lit_by_one_pixels=int((classes == 5).sum()),
        cycles_shadowed_pixels=int((compared & cycles_dark).sum()),
        csm_shadowed_pixels=int((compared & csm_dark).sum()))
    return result, classes


def heatmap(classes):
    """(H, W, 3) uint8 colours for a class image."""
    palette = np.array([COLOR_EXCLUDED, COLOR_AGREE_LIT, COLOR_AGREE_SHADOW,
                        COLOR_FALSE_SHADOW, COLOR_MISSED_SHADOW, COLOR_LIT_BY_ONE],
                       dtype=np.uint8)
    return palette[classes]


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


def _isolate_sun(scene, changes):
    """Hide every light but CSM's sun and black out the world, for both engines."""
    sun = _sun_used_by_csm(scene)
    if sun is None:
        raise CLIError("the scene has no sun (directional light): there is no sun shadow "
                       "to compare", EXIT_SCENE)
    for obj in scene.objects:
        if obj.type == 'LIGHT' and obj != sun:
            changes.set(obj, "hide_render", True)
    changes.set(sun.data, "angle", 0.0)          # a point-like sun: exact hard shadows
    changes.set(scene, "world", None)            # no ambient / world light in either engine
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
    """CSM's combined RGB and aux (H, W, 4), rows bottom-to-top."""
    from csm_engine.blender import engine
    scene.render.engine = "CSM"
    result = engine.render_final(scene, keep_images=True)
    if result.error:
        raise CLIError("CSM render failed: " + result.error, EXIT_RENDER)
    images = result.images
    return images["combined"][..., :3].astype(np.float64), images["aux"].astype(np.float64)


def _setup_cycles(scene, changes):
    cycles = scene.cycles
    for name, value in (("device", 'CPU'), ("samples", 1), ("use_adaptive_sampling", False),
                        ("use_denoising", False), ("max_bounces", 0),
                        # Shadow rays pass through alpha-cut texels (leaves, grilles) as
                        # CSM's masked shadow pass does; 0 made them solid cards.
                        ("transparent_max_bounces", TRANSPARENT_BOUNCES),
                        ("pixel_filter_type", 'BOX'),
                        ("filter_width", 0.01), ("seed", 0), ("use_animated_seed", False),
                        ("sample_clamp_direct", 0.0)):
        changes.set(cycles, name, value)
    changes.set(scene.render, "use_compositing", False)
    changes.set(scene.render, "use_sequencer", False)
    image = scene.render.image_settings
    changes.set(image, "file_format", 'OPEN_EXR')
    changes.set(image, "color_depth", '32')
    changes.set(image, "color_mode", 'RGB')
    changes.set(scene.render, "use_file_extension", True)


def _render_cycles(scene, changes, path):
    """Cycles' combined RGB (H, W, 3), rows bottom-to-top, via a float EXR file."""
    import bpy
    from csm_engine.blender import engine
    scene.render.engine = "CYCLES"
    changes.set(scene.render, "filepath", path)
    engine.render_final(scene, write_still=True)
    if not os.path.isfile(path):
        raise CLIError(f"Cycles render finished but '{path}' was not written", EXIT_RENDER)
    image = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * image.channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        rgb = pixels.reshape(height, width, image.channels)[..., :3].astype(np.float64)
    finally:
        bpy.data.images.remove(image)
    return rgb


@dataclasses.dataclass
class EngineVisibility:
    """One engine's sun visibility at one image size: ``vis`` (H, W) on / off, ``lit``
    (H, W) the pixels the sun lights with shadows off; ``aux`` is CSM's auxiliary target
    (None for Cycles). Rows run bottom-to-top as GL and Blender store them."""
    vis: np.ndarray
    lit: np.ndarray
    aux: object = None


@contextlib.contextmanager
def _isolated(scene, width, height):
    """The measurement set-up (only CSM's sun, black world, ``width`` x ``height``);
    yields (sun, changes) and puts everything back afterwards."""
    changes = _Changes()
    engine_before = scene.render.engine
    try:
        sun = _isolate_sun(scene, changes)
        changes.set(sun.data, "use_shadow", sun.data.use_shadow)
        cycles_light = getattr(sun.data, "cycles", None)
        if cycles_light is not None and hasattr(cycles_light, "cast_shadow"):
            changes.set(cycles_light, "cast_shadow", cycles_light.cast_shadow)
        changes.set(scene.render, "resolution_x", width)
        changes.set(scene.render, "resolution_y", height)
        # Pixel centres, as Cycles' 0.01-pixel box filter sees them: no anti-aliasing.
        changes.set(scene.csm, "render_samples", 1)
        changes.set(scene.csm, "fxaa", False)
        yield sun, changes
    finally:
        changes.restore()
        scene.render.engine = engine_before


def csm_visibility(scene, width, height):
    """Render CSM twice (sun shadows on, off) with the scene's current CSM settings."""
    with _isolated(scene, width, height) as (sun, _changes):
        _set_sun_shadow(sun, True)
        csm_on, aux = _render_csm(scene)
        _set_sun_shadow(sun, False)
        csm_off, _ = _render_csm(scene)
    off_sum = csm_off.sum(axis=2)
    # CSM's coverage channel is 0 on the background, whatever the colour says.
    return EngineVisibility(vis=visibility_from_on_off(csm_on.sum(axis=2), off_sum),
                            lit=lit_mask(off_sum) & (aux[..., 3] > 0.5), aux=aux)


def cycles_visibility(scene, width, height):
    """The reference: render Cycles twice (sun shadows on, off). It does not depend on any
    CSM setting, so one reference serves every CSM setting on the same scene and size."""
    with _isolated(scene, width, height) as (sun, changes):
        _setup_cycles(scene, changes)
        with tempfile.TemporaryDirectory(prefix="csm_ground_truth_") as folder:
            _set_sun_shadow(sun, True)
            cycles_on = _render_cycles(scene, changes, os.path.join(folder, "on.exr"))
            _set_sun_shadow(sun, False)
            cycles_off = _render_cycles(scene, changes, os.path.join(folder, "off.exr"))
    off_sum = cycles_off.sum(axis=2)
    return EngineVisibility(vis=visibility_from_on_off(cycles_on.sum(axis=2), off_sum),
                            lit=lit_mask(off_sum))


def compare_engines(csm, cycles):
    """Compare CSM's ``EngineVisibility`` with Cycles'; returns (Comparison, class image
    with rows bottom-to-top), including the aux cross-check."""
    result, classes = compare(csm.vis, cycles.vis, csm.lit, cycles.lit)
    compared = csm.lit & cycles.lit
    aux_vis = csm.aux[..., 0]
    result.aux_classified_differently = int(
        ((aux_vis < SHADOWED_BELOW) != (csm.vis < SHADOWED_BELOW))[compared].sum())
    result.aux_max_difference = float(np.abs(aux_vis - csm.vis)[compared].max()) \
        if compared.any() else 0.0
    return result, classes


def measure(scene, width, height, heatmap_path=None):
    """Render ``scene`` four times and compare CSM's sun visibility with Cycles'.

    Returns a ``Comparison``; writes the heat map (PNG) when ``heatmap_path`` is given.
    The scene is left as it was found. To compare many CSM settings on one scene, call
    ``cycles_visibility`` once and ``csm_visibility`` + ``compare_engines`` per setting
    (``quality_report.py`` does).
    """
    csm = csm_visibility(scene, width, height)
    cycles = cycles_visibility(scene, width, height)
    result, classes = compare_engines(csm, cycles)
    if heatmap_path:
        write_png(heatmap_path, heatmap(classes)[::-1])   # PNG rows run top to bottom
    return result


# ------------------------------------------------------------------------ command line

def build_parser(prog=PROG):
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Compare CSM's sun shadows with Cycles' ray-traced hard shadows on a "
                    "JSON scene; report mismatch %, false shadow % (CSM dark, Cycles lit) "
                    "and missed shadow % (CSM lit, Cycles dark).")
    parser.add_argument("scene", nargs="?", help="scene .json (default: the bundled scene)")
    parser.add_argument("--resolution", default=DEFAULT_RESOLUTION, metavar="WxH",
                        help=f"image size in pixels (default {DEFAULT_RESOLUTION})")
    parser.add_argument("--heatmap", metavar="PNG",
                        help="write a heat map: grey = agree (light lit, dark shadowed), "
                             "red = false shadow, blue = missed shadow, yellow = lit by one "
                             "engine only, black = not compared")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="SETTING=VALUE",
                        help="override a CSM setting, e.g. --set depth_bias=0 (repeatable)")
    parser.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    parser.add_argument("--max-mismatch", type=float, metavar="PERCENT",
                        help="exit with code 1 when the mismatch exceeds PERCENT")
    return parser


def run(argv, prog=PROG):
    args = build_parser(prog).parse_args(argv)
    width, height = parse_resolution(args.resolution)
    for label, path in (("--heatmap", args.heatmap), ("--json", args.json)):
        if path:
            folder = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(folder):
                raise CLIError(f"{label}: cannot write '{path}': folder '{folder}' "
                               "does not exist")

    from csm_engine.core import paths
    scene_path = args.scene or paths.default_scene_path()
    scene = open_scene(scene_path, args.overrides, (width, height))
    if not hasattr(scene, "cycles"):
        raise CLIError("Cycles is not available in this Blender: enable the Cycles add-on",
                       EXIT_RENDER)

    result = measure(scene, width, height, args.heatmap)
    settings = ", ".join(args.overrides) if args.overrides else "defaults"
    print(f"ground truth: {scene_path} at {width}x{height}, CSM settings: {settings}")
    print(result.summary())
    if args.heatmap:
        print(f"heat map: {os.path.abspath(args.heatmap)}")
    if args.json:
        values = result.as_dict()
        values.update(scene=os.path.abspath(scene_path), overrides=list(args.overrides))
        with open(args.json, "w", encoding="utf-8") as stream:
            json.dump(values, stream, indent=2)
    if args.max_mismatch is not None and result.mismatch_percent > args.max_mismatch:
        print(f"ground truth: mismatch {result.mismatch_percent:.3f} % exceeds "
              f"{args.max_mismatch:g} %", file=sys.stderr)
        return 1
    return 0


def main(argv=None, prog=PROG):
    return run_reporting_errors(run, argv, prog, "ground truth")


if __name__ == "__main__":
    from csm_engine.blender.compat import exit_process
    exit_process(main())
