"""The ground-truth tool's EEVEE column, soft mode, lit-pixel figures and texel density.

Every engine is measured against the same Cycles reference in one process. The tests check
that the numbers mean what the docs say: EEVEE's exist and are judged on CSM's pixels, a
deliberately bad CSM bias shows as false shadow and as partial shadow on lit pixels, the
sun's angle reaches every engine (Cycles' penumbra widens with it), CSM's penumbra widens
with its PCF kernel, and halving the shadow-map resolution doubles the texel footprint.
Small images (160x90 to 240x135) and few Cycles samples keep them quick.
"""
import json
import math
import os

import bpy
import numpy as np
import pytest

from tests.conftest import SCENES
from csm_tools import ground_truth
from csm_tools.report_io import read_png

SIZE = (160, 90)
SOFT_SAMPLES = 32          # Cycles; enough for the penumbra counts at this size


def count_color(image, color):
    return int(np.all(image == np.array(color, dtype=np.uint8), axis=2).sum())


def shadow_test(*overrides, size=SIZE):
    scene, _ = ground_truth.open_named_scene("shadow_test", list(overrides), size)
    return scene


# ------------------------------------------------------------------------ pure numpy

def test_partial_shadow_and_flat_ground_are_counted_on_cycles_fully_lit_pixels():
    cycles = np.array([[1.0, 1.0, 1.0, 0.0]])
    engine = np.array([[1.0, 0.99, 0.2, 0.0]])
    lit = np.ones_like(cycles, dtype=bool)
    flat = np.array([[True, True, False, True]])
    result, classes = ground_truth.compare(engine, cycles, lit, lit, flat=flat)
    assert result.cycles_fully_lit_pixels == 3
    assert result.partial_on_lit_pixels == 2             # 0.99 and 0.2
    assert result.partial_on_lit_percent == pytest.approx(200.0 / 3)
    assert result.flat_lit_ground_pixels == 2            # the shadowed flat pixel is not lit
    assert result.flat_ground_full_fraction == pytest.approx(0.5)
    assert result.mean_abs_error == pytest.approx((0.01 + 0.8) / 4)
    assert result.mean_signed_error == pytest.approx(-(0.01 + 0.8) / 4)
    assert list(classes[0]) == [1, 1, 3, 2]


def test_flat_ground_short_of_lit_is_split_by_whether_it_touches_a_shadow():
    # Row 0: a shadow edge at the right; the pixel beside it falls short (filter reach),
    # the one two pixels away falls short too (a stripe, not the edge's doing).
    cycles = np.array([[1.0, 1.0, 1.0, 1.0, 0.0],
                       [1.0, 1.0, 1.0, 1.0, 1.0]])
    engine = np.array([[1.0, 0.9, 1.0, 0.8, 0.0],
                       [1.0, 1.0, 1.0, 1.0, 1.0]])
    lit = np.ones_like(cycles, dtype=bool)
    result, _ = ground_truth.compare(engine, cycles, lit, lit, flat=lit)
    assert result.flat_lit_ground_pixels == 9
    assert result.flat_lit_ground_full_pixels == 7
    assert result.flat_lit_ground_short_at_edge_pixels == 1
    assert result.flat_ground_short_at_edge_fraction == pytest.approx(0.5)
    # Without the three flat lit pixels touching the shadow, 5 of the other 6 are lit.
    assert result.flat_lit_ground_at_edge_pixels == 3
    assert result.flat_ground_away_from_edges_full_fraction == pytest.approx(5.0 / 6.0)


def test_flat_ground_whole_pixel_figure_leaves_out_the_pixels_an_edge_crosses():
    # Row 0: Cycles' centre samples light the first four pixels; a shadow edge crosses the
    # fourth (lit at its centre, not over its whole area), where a filter reads 0.8. The
    # second pixel no edge touches reads 0.9: a stripe, which the whole-pixel figure sees.
    cycles = np.array([[1.0, 1.0, 1.0, 1.0, 0.0]])
    engine = np.array([[1.0, 0.9, 1.0, 0.8, 0.0]])
    whole = np.array([[True, True, True, False, False]])
    lit = np.ones_like(cycles, dtype=bool)
    result, _ = ground_truth.compare(engine, cycles, lit, lit, flat=lit, whole_lit=whole)
    assert result.flat_ground_full_fraction == pytest.approx(0.5)
    assert result.flat_whole_lit_ground_pixels == 3
    assert result.flat_whole_lit_ground_full_pixels == 2
    assert result.flat_ground_whole_pixel_full_fraction == pytest.approx(2.0 / 3.0)
    without, _ = ground_truth.compare(engine, cycles, lit, lit, flat=lit)
    assert without.flat_ground_whole_pixel_full_fraction is None


def test_blurring_a_hard_edge_toward_the_reference_lowers_the_error():
    """The continuous error prefers the right penumbra: a soft reference edge, a hard
    engine edge and one blurred like the reference."""
    x = np.linspace(-1.0, 1.0, 200)
    reference = np.clip(0.5 + x / 0.4, 0.0, 1.0)[None, :].repeat(4, axis=0)
    hard = (x > 0.0).astype(float)[None, :].repeat(4, axis=0)
    close = np.clip(0.5 + x / 0.3, 0.0, 1.0)[None, :].repeat(4, axis=0)
    lit = np.ones_like(reference, dtype=bool)
    hard_result, _ = ground_truth.compare(hard, reference, lit, lit)
    close_result, _ = ground_truth.compare(close, reference, lit, lit)
    assert close_result.mean_abs_error < 0.5 * hard_result.mean_abs_error
    assert hard_result.penumbra_width_error_percent == pytest.approx(-100.0)
    assert -35.0 < close_result.penumbra_width_error_percent < -15.0


def test_signed_error_heat_map_colours():
    cycles = np.array([[1.0, 1.0, 0.0, 0.5]])
    engine = np.array([[1.0, 0.0, 1.0, 0.5]])
    classes = np.array([[1, 3, 4, 0]], dtype=np.uint8)
    image = ground_truth.signed_error_heatmap(engine, cycles, classes)
    assert tuple(image[0, 0]) == ground_truth.COLOR_AGREE_LIT
    assert tuple(image[0, 1]) == ground_truth.COLOR_FALSE_SHADOW       # darker than Cycles
    assert tuple(image[0, 2]) == ground_truth.COLOR_MISSED_SHADOW      # lighter
    assert tuple(image[0, 3]) == ground_truth.COLOR_EXCLUDED


def test_pixel_size_and_texel_footprint_on_a_tilted_plane():
    """A plane seen with pixels 0.1 wide along x and 0.3 along y; texels of 0.6 in
    cascade 0 and 1.2 in cascade 1: footprints 2 and 4 pixels; a cascade value of 0.5
    (a blend band) interpolates to 3."""
    height, width = 20, 30
    y, x = np.mgrid[0:height, 0:width].astype(float)
    position = np.stack([0.1 * x, 0.3 * y, 0.05 * y], axis=-1)
    covered = np.ones((height, width), dtype=bool)
    covered[:, 0] = False                               # a silhouette: no position there
    position[:, 0] = 1e6
    size = ground_truth.pixel_world_size(position, covered)
    assert np.isnan(size[:, 0]).all()
    assert np.allclose(size[:, 1:], math.hypot(0.3, 0.05))
    cascade = np.zeros((height, width))
    cascade[:, 15:] = 1.0
    mask = covered.copy()
    density = ground_truth.texel_density(position, cascade, [0.6, 1.2], mask)
    step = math.hypot(0.3, 0.05)
    assert density.p10_footprint_px == pytest.approx(0.6 / step)
    assert density.p90_footprint_px == pytest.approx(1.2 / step)
    assert density.cascade_share == pytest.approx([14 / 29, 15 / 29])
    cascade[:] = 0.5
    assert ground_truth.texel_density(position, cascade, [0.6, 1.2], mask) \
        .median_footprint_px == pytest.approx(0.9 / step)


# ------------------------------------------------------------------------------ renders

_HARD = {}


def hard_run(tmp_dir):
    """shadow_test, hard mode, CSM and EEVEE, through the command (JSON and heat maps)."""
    if not _HARD:
        numbers_path = os.path.join(tmp_dir, "hard.json")
        heat_path = os.path.join(tmp_dir, "hard.png")
        argv = [os.path.join(SCENES, "shadow_test.json"), "--resolution", "240x135",
                "--heatmap", heat_path, "--json", numbers_path]
        assert ground_truth.main(argv) == 0
        with open(numbers_path, encoding="utf-8") as stream:
            _HARD["numbers"] = json.load(stream)
        _HARD["csm_heat"] = read_png(heat_path)
        _HARD["eevee_heat"] = read_png(ground_truth.eevee_heatmap_path(heat_path))
    return _HARD


@pytest.fixture(scope="module")
def tmp_dir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("ground_truth_modes"))


def test_eevee_is_measured_beside_csm_on_the_same_pixels(tmp_dir):
    run = hard_run(tmp_dir)
    numbers = run["numbers"]
    csm, eevee = numbers["csm"], numbers["eevee"]
    assert numbers["mode"] == "hard" and numbers["cycles_samples"] == 1
    assert numbers["eevee_engine"] in ("BLENDER_EEVEE", "BLENDER_EEVEE_NEXT")
    assert eevee["engine"] == "EEVEE" and csm["engine"] == "CSM"
    # One Cycles reference, one set of compared pixels for both engines.
    assert csm["compared_pixels"] == eevee["compared_pixels"] > 0.3 * 240 * 135
    assert csm["cycles_shadowed_pixels"] == eevee["cycles_shadowed_pixels"] > 50
    # EEVEE really shadows what Cycles shadows: far from "everything lit".
    assert eevee["mismatch_percent"] < 5.0
    assert eevee["shadow_lost_percent"] < 50.0
    assert 0.0 < eevee["seconds"] and 0.0 < csm["seconds"]
    if eevee["mismatch_percent"] > 0:
        assert numbers["csm_over_eevee"]["mismatch_percent"] == pytest.approx(
            csm["mismatch_percent"] / eevee["mismatch_percent"])
    # The top-level numbers stay CSM's (scripts written before EEVEE read them).
    assert numbers["mismatch_percent"] == csm["mismatch_percent"]
    # Each heat map paints exactly its engine's counted pixels.
    assert count_color(run["eevee_heat"], ground_truth.COLOR_FALSE_SHADOW) == \
        eevee["false_shadow_pixels"]
    assert count_color(run["eevee_heat"], ground_truth.COLOR_MISSED_SHADOW) == \
        eevee["missed_shadow_pixels"]
    assert count_color(run["csm_heat"], ground_truth.COLOR_MISSED_SHADOW) == \
        csm["missed_shadow_pixels"]
    # shadow_test looks down at flat ground: the flat-ground figure has pixels to judge.
    assert csm["flat_lit_ground_pixels"] > 0.3 * csm["compared_pixels"]
    assert eevee["flat_ground_full_fraction"] > 0.99
    assert numbers["texel_density"]["pixels"] > 0.9 * csm["compared_pixels"]


def test_zero_bias_shows_as_partial_shadow_on_fully_lit_pixels():
    scene = shadow_test()
    good = ground_truth.measure_report(scene, *SIZE, eevee=False).csm
    acne_scene = shadow_test("depth_bias=0", "slope_bias=0", "normal_offset=0")
    acne = ground_truth.measure_report(acne_scene, *SIZE, eevee=False).csm
    assert acne.false_shadow_percent > 10.0 > good.false_shadow_percent
    assert acne.partial_on_lit_percent > 20.0
    assert acne.partial_on_lit_percent > 5 * max(good.partial_on_lit_percent, 0.1)
    assert acne.flat_ground_full_fraction < 0.9 < good.flat_ground_full_fraction
    assert acne.mean_abs_error > 5 * good.mean_abs_error


def test_the_sun_angle_reaches_every_engine_and_is_restored():
    scene = shadow_test()
    sun = ground_truth._sun_used_by_csm(scene)
    angle_before = sun.data.angle
    samples_before = scene.eevee.taa_render_samples
    filter_before = scene.render.filter_size
    engine_before = scene.render.engine
    hard = ground_truth.measure_report(scene, *SIZE, eevee=False)
    wide = ground_truth.measure_report(scene, *SIZE, sun_angle=10.0,
                                       cycles_samples=SOFT_SAMPLES, eevee_samples=4)
    assert hard.mode == "hard" and wide.mode == "soft"
    assert hard.csm.penumbra_width_ratio is None           # Cycles' hard edge: no penumbra
    assert hard.csm.cycles_penumbra_pixels < 20
    # A 10 degree sun behind 6-unit pillars: penumbrae Cycles and EEVEE both draw (70
    # pixels through pixel centres; 100+ while the reference sampled whole pixels).
    assert wide.csm.cycles_penumbra_pixels > 40
    assert wide.eevee.penumbra_pixels > 0.2 * wide.csm.cycles_penumbra_pixels
    assert wide.cycles_samples == SOFT_SAMPLES and wide.eevee_samples == 4
    assert 0.0 < wide.cycles_noise < 0.05
    assert wide.eevee.mean_abs_error < 0.05
    assert sun.data.angle == pytest.approx(angle_before)
    assert scene.eevee.taa_render_samples == samples_before
    assert scene.render.filter_size == pytest.approx(filter_before)
    assert scene.render.engine == engine_before


def test_csm_penumbra_widens_with_its_kernel_in_soft_mode():
    """A wrong kernel shows: the fixed PCF filter without a kernel gives CSM a narrower
    penumbra than Cycles' 10 degree sun, a 3-texel PCF a wider one than no PCF."""
    narrow = ground_truth.measure_report(shadow_test("shadow_filter=PCF", "pcf_radius=0"),
                                         240, 135, sun_angle=10.0, eevee=False,
                                         cycles_samples=SOFT_SAMPLES, csm_shadow_filter=None)
    wide = ground_truth.measure_report(shadow_test("shadow_filter=PCF", "pcf_radius=3"),
                                       240, 135, sun_angle=10.0, eevee=False,
                                       cycles_samples=SOFT_SAMPLES, csm_shadow_filter=None)
    assert narrow.csm.penumbra_width_error_percent < -30.0
    assert wide.csm.penumbra_pixels > 1.5 * narrow.csm.penumbra_pixels


def test_soft_mode_uses_csm_soft_filter_when_it_exists():
    """Once CSM has ``shadow_filter``: soft mode sets 'SOFT' unless --set names it, and
    the soft filter beats the hard one against Cycles' 3 degree sun."""
    scene = shadow_test()
    if not hasattr(scene.csm, "shadow_filter"):
        pytest.skip("CSM has no shadow_filter setting yet")
    soft = ground_truth.measure_report(scene, *SIZE, sun_angle=3.0, eevee=False,
                                       cycles_samples=SOFT_SAMPLES)
    assert soft.csm_shadow_filter == 'SOFT'
    hard = ground_truth.measure_report(shadow_test("shadow_filter=HARD"), *SIZE,
                                       sun_angle=3.0, eevee=False,
                                       cycles_samples=SOFT_SAMPLES, csm_shadow_filter=None)
    assert hard.csm_shadow_filter is None
    assert soft.csm.mean_abs_error < hard.csm.mean_abs_error


def test_halving_the_shadow_map_doubles_the_texel_footprint():
    fine = ground_truth.measure_report(shadow_test("resolution=2048"), *SIZE,
                                       eevee=False).texel
    coarse = ground_truth.measure_report(shadow_test("resolution=1024"), *SIZE,
                                         eevee=False).texel
    assert fine.pixels > 1000
    assert coarse.median_footprint_px / fine.median_footprint_px == pytest.approx(2.0,
                                                                                  rel=0.1)
    assert fine.p10_footprint_px < fine.median_footprint_px < fine.p90_footprint_px
    assert sum(fine.cascade_share) == pytest.approx(1.0)


def test_fully_lit_flat_ground_is_measured_on_a_plain_plane(empty_scene):
    """A plane under a low sun and nothing else: Cycles lights it all, so every compared
    pixel is fully lit flat ground; EEVEE shows it lit. CSM's figure is the issue's
    acceptance line (printed here, asserted by the lead's shadow tests)."""
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=200)
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(75), 0.0, math.radians(30)))
    bpy.ops.object.camera_add(location=(0.0, -30.0, 8.0), rotation=(math.radians(70), 0, 0))
    scene.camera = bpy.context.object
    report = ground_truth.measure_report(scene, *SIZE)
    csm, eevee = report.csm, report.eevee
    assert csm.compared_pixels > 0.4 * SIZE[0] * SIZE[1]
    assert csm.flat_lit_ground_pixels == csm.compared_pixels == eevee.compared_pixels
    assert csm.cycles_shadowed_pixels == 0
    assert eevee.flat_ground_full_fraction > 0.999
    print(f"flat lit ground at >= 0.999: CSM {csm.flat_ground_full_fraction:.4f}, "
          f"EEVEE {eevee.flat_ground_full_fraction:.4f}")


def _slab_shadow_scene(scene):
    """A tilted slab on a plane, its shadow thrown toward the camera: long edges at every
    angle to the pixel grid."""
    bpy.ops.mesh.primitive_plane_add(size=200)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 2.0),
                                    rotation=(0.0, 0.0, math.radians(27)))
    bpy.context.object.scale = (8.0, 0.5, 3.0)
    # The sun behind the camera's side: the shadow falls toward the camera, in view.
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(-40), 0.0, math.radians(10)))
    bpy.ops.object.camera_add(location=(0.0, -20.0, 14.0), rotation=(math.radians(55), 0, 0))
    scene.camera = bpy.context.object
    return scene


def test_cycles_reference_samples_pixel_centres(empty_scene):
    """The reference takes its rays through each pixel's centre, where CSM and EEVEE shade:
    with many samples and a hard sun, a shadow edge stays a step. Cycles' box filter would
    not do (it is one pixel wide whatever its width): through it, the pixels an edge
    crosses come out partly shadowed."""
    scene = _slab_shadow_scene(empty_scene)
    width, height = SIZE
    centre = ground_truth.cycles_visibility(scene, width, height, samples=16)
    box = ground_truth._reference_visibility(
        scene, width, height, 0.0, "CYCLES",
        lambda changes: ground_truth._setup_cycles_whole_pixel(scene, changes, 16), 16)

    def partial(result):
        return int((result.lit & (result.vis > 0.05) & (result.vis < 0.95)).sum())

    assert partial(box) > 50, partial(box)
    assert partial(centre) <= 0.1 * partial(box), (partial(centre), partial(box))
    print(f"partly shadowed pixels, 16 samples: centre {partial(centre)}, whole pixel "
          f"{partial(box)}")


def test_whole_pixel_lit_ground_leaves_out_just_the_pixels_a_shadow_edge_crosses(
        empty_scene):
    """A tilted slab's shadow on a plane: Cycles' whole-pixel mask drops some pixels its
    centre samples call lit, every one of them beside a centre-shadowed pixel (an edge
    crosses them), and keeps the open ground. On it CSM's flat lit ground is at least as
    full as on the centre-lit pixels."""
    scene = _slab_shadow_scene(empty_scene)
    width, height = SIZE
    centre = ground_truth.cycles_visibility(scene, width, height)
    whole = ground_truth.cycles_whole_pixel_lit(scene, width, height)
    centre_lit = centre.lit & (centre.vis >= ground_truth.FULLY_LIT)
    centre_dark = centre.lit & (centre.vis < ground_truth.SHADOWED_BELOW)
    assert centre_dark.sum() > 1000                      # the slab's shadow is in view
    # A pixel shadowed at its centre is never whole-lit. (On silhouettes, where part of
    # the pixel is a face turned from the sun, it can be; compare() takes only pixels
    # lit at their centre too.)
    assert not (whole & centre.lit & ~centre_lit).any()
    crossed = centre_lit & ~whole
    assert crossed.sum() >= 10
    assert not (crossed & ~ground_truth._next_to(centre_dark | ~centre.lit)).any()
    assert whole.sum() > 0.9 * centre_lit.sum()
    report = ground_truth.measure_report(scene, width, height, eevee=False)
    csm = report.csm
    assert 0 < csm.flat_whole_lit_ground_pixels < csm.flat_lit_ground_pixels
    assert csm.flat_ground_whole_pixel_full_fraction >= csm.flat_ground_full_fraction
    print(f"crossed by an edge: {int(crossed.sum())} of {int(centre_lit.sum())} centre-lit; "
          f"flat lit ground at >= 0.999: centre {csm.flat_ground_full_fraction:.4f}, whole "
          f"pixel {csm.flat_ground_whole_pixel_full_fraction:.4f}")


def test_command_rejects_bad_soft_mode_options(capsys):
    scene = os.path.join(SCENES, "shadow_test.json")
    assert ground_truth.main([scene, "--sun-angle", "-3"]) == 2
    assert ground_truth.main([scene, "--cycles-samples", "0"]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines()
              if line.startswith("ground truth: error:")]
    assert len(errors) == 2
    assert "--sun-angle" in errors[0] and "--cycles-samples" in errors[1]


@pytest.mark.parametrize("geometry_offset", [0.0, 0.1])
def test_a_low_poly_smooth_spheres_terminator_follows_its_geometry_offset(empty_scene,
                                                                          geometry_offset):
    """The shadow terminator as Cycles draws it (soft-shadows.md): on a 12-segment sphere
    shaded smooth, the terminator band (facets turned away from the sun, smooth-shaded
    toward it) shadows itself when the object's Shadow Terminator Geometry Offset is 0 (a
    stepped terminator) and is lit at Blender's default 0.1, where Cycles moves its shadow
    rays onto the smooth surface and CSM lifts the lookup to about that surface. The
    facets facing the sun are lit either way; over the whole sphere CSM and Cycles
    disagree on under 2 % of the pixels. Facets are told apart by the true face normal
    (``scene.ray_cast`` from the camera)."""
    import mathutils
    scene = empty_scene
    width, height = 320, 180
    bpy.ops.mesh.primitive_plane_add(size=40)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=2.0,
                                         location=(0.0, 0.0, 2.2))
    bpy.ops.object.shade_smooth()
    sphere_object = bpy.context.object
    # An Object property in 5.0, the Cycles add-on's before.
    owner = sphere_object if hasattr(sphere_object, "shadow_terminator_geometry_offset") \
        else sphere_object.cycles
    owner.shadow_terminator_geometry_offset = geometry_offset
    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(60), 0.0, math.radians(90)))
    sun = bpy.context.object
    bpy.ops.object.camera_add(location=(0.0, -12.0, 4.0), rotation=(math.radians(80), 0, 0))
    scene.camera = bpy.context.object
    csm = ground_truth.csm_visibility(scene, width, height)
    cycles = ground_truth.cycles_visibility(scene, width, height)

    to_sun = sun.matrix_world.to_3x3() @ mathutils.Vector((0.0, 0.0, 1.0))
    eye = scene.camera.matrix_world.translation
    depsgraph = bpy.context.evaluated_depsgraph_get()
    shading_to_sun = csm.normal @ np.array(to_sun)
    sphere = np.zeros((height, width), dtype=bool)
    band = np.zeros_like(sphere)
    facing = np.zeros_like(sphere)
    for row, column in zip(*np.nonzero(csm.lit & cycles.lit)):
        ray = mathutils.Vector(csm.position[row, column]) - eye
        hit, _, face_normal, _, obj, _ = scene.ray_cast(
            depsgraph, eye, ray.normalized(), distance=ray.length * 1.001 + 1e-3)
        if hit and obj.name.startswith("Sphere"):
            sphere[row, column] = True
            turned_away = face_normal.dot(to_sun) <= 0.0
            band[row, column] = turned_away and shading_to_sun[row, column] > 0.0
            facing[row, column] = not turned_away
    assert band.sum() > 200 and facing.sum() > 2000
    csm_band_dark = np.mean(csm.vis[band] < 0.5)
    cycles_band_dark = np.mean(cycles.vis[band] < 0.5)
    if geometry_offset == 0.0:
        assert cycles_band_dark > 0.95 and csm_band_dark > 0.7      # stepped
    else:
        assert cycles_band_dark < 0.05 and csm_band_dark < 0.2      # smooth
    assert np.mean(csm.vis[facing] >= 0.5) > 0.995                   # no acne on lit facets
    assert np.mean(cycles.vis[facing] >= 0.5) > 0.995
    assert np.mean((csm.vis[sphere] < 0.5) != (cycles.vis[sphere] < 0.5)) < 0.02
