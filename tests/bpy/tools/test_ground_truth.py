"""The ground-truth tool: CSM's sun shadows against Cycles' ray-traced hard shadows.

The acceptance line: with the default settings the tool reports under 1% mismatch on each
of the project's test scenes. The tool must also be able to fail: with
the biases at zero it reports acne (false shadow), with a huge bias peter-panning (missed
shadow), and its heat map shows the same pixels it counts.
"""
import json
import os

import bpy
import numpy as np
import pytest

from tests.bpy.tools.tool_helpers import run_module
from tests.conftest import REPO, SCENES
from csm_tools import ground_truth
from csm_tools.report_io import read_png

RESOLUTION = "480x270"
RED, BLUE = ground_truth.COLOR_FALSE_SHADOW, ground_truth.COLOR_MISSED_SHADOW

_RUNS = {}


def run_tool(tmp_dir, scene, *overrides):
    """Run the command in-process once per (scene, settings); returns (numbers, heat map
    as (H, W, 3) uint8 with the top row first, as the PNG shows it)."""
    key = (scene,) + overrides
    if key not in _RUNS:
        stem = "_".join(part.replace("=", "-") for part in key)
        numbers_path = os.path.join(tmp_dir, stem + ".json")
        heatmap_path = os.path.join(tmp_dir, stem + ".png")
        argv = [os.path.join(SCENES, scene + ".json"), "--resolution", RESOLUTION,
                "--heatmap", heatmap_path, "--json", numbers_path]
        for override in overrides:
            argv += ["--set", override]
        assert ground_truth.main(argv) == 0
        with open(numbers_path, encoding="utf-8") as stream:
            numbers = json.load(stream)
        _RUNS[key] = numbers, read_png(heatmap_path)
    return _RUNS[key]


def count_color(image, color):
    return int(np.all(image == np.array(color, dtype=np.uint8), axis=2).sum())


@pytest.fixture(scope="module")
def tmp_dir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("ground_truth"))


@pytest.mark.parametrize("scene", ["shadow_test", "default", "point_lights"])
def test_defaults_match_cycles_within_one_percent(tmp_dir, scene):
    numbers, _ = run_tool(tmp_dir, scene)
    width, height = (int(v) for v in RESOLUTION.split("x"))
    # A comparison of nothing would pass trivially: the scene must show lit ground and
    # shadows that Cycles ray traced.
    assert numbers["compared_pixels"] > 0.3 * width * height
    assert numbers["cycles_shadowed_pixels"] > 300
    assert numbers["mismatch_percent"] < 1.0, (
        f"{scene}: mismatch {numbers['mismatch_percent']:.2f} % (false shadow "
        f"{numbers['false_shadow_percent']:.2f} %, missed shadow "
        f"{numbers['missed_shadow_percent']:.2f} %; CSM lit "
        f"{numbers['shadow_lost_percent']:.1f} % of Cycles' shadowed pixels)")


@pytest.mark.parametrize("scene", ["shadow_test", "default", "point_lights"])
def test_defaults_keep_the_shadows_cycles_casts(tmp_dir, scene):
    """No visible peter-panning. On shadow_test the shadows cover under 1% of
    the image, so CSM could drop every one of them and still pass the mismatch line; the
    share of Cycles' shadowed pixels that CSM shows lit catches that."""
    numbers, _ = run_tool(tmp_dir, scene)
    assert numbers["shadow_lost_percent"] < 10.0, (
        f"{scene}: CSM lit {numbers['shadow_lost_percent']:.1f} % of the "
        f"{numbers['cycles_shadowed_pixels']} pixels Cycles shadows")


def test_csm_visibility_channel_equals_its_on_off_ratio(tmp_dir):
    """The ratio method measures exactly what the shader writes as sun visibility."""
    numbers, _ = run_tool(tmp_dir, "shadow_test")
    assert numbers["aux_classified_differently"] == 0
    assert numbers["aux_max_difference"] < 1e-3


def test_zero_bias_is_reported_as_false_shadow(tmp_dir):
    good, _ = run_tool(tmp_dir, "shadow_test")
    acne, heat = run_tool(tmp_dir, "shadow_test", "depth_bias=0", "slope_bias=0",
                          "normal_offset=0")
    assert acne["false_shadow_percent"] > 10.0
    assert acne["false_shadow_percent"] > 20 * max(good["false_shadow_percent"], 0.01)
    assert acne["mismatch_percent"] > 10.0
    # The heat map paints exactly the counted pixels red.
    assert count_color(heat, RED) == acne["false_shadow_pixels"]
    assert count_color(heat, BLUE) == acne["missed_shadow_pixels"]


@pytest.mark.parametrize("scene", ["shadow_test", "default"])
def test_huge_bias_is_reported_as_missed_shadow(tmp_dir, scene):
    good, _ = run_tool(tmp_dir, scene)
    # Texels are small since the cascades fit the visible depth: 1000 of them is still a bias
    # of metres, far past every caster.
    floating, heat = run_tool(tmp_dir, scene, "depth_bias=1000", "normal_offset=10")
    assert floating["missed_shadow_percent"] > 2 * max(good["missed_shadow_percent"], 0.01)
    assert floating["shadow_lost_percent"] > 90.0
    assert count_color(heat, BLUE) == floating["missed_shadow_pixels"]
    if scene == "default":
        # Shadows cover a fifth of this view: losing them fails the 1% line by far.
        assert floating["mismatch_percent"] > 10.0


def test_heat_map_is_upright_and_counts_match(tmp_dir):
    numbers, heat = run_tool(tmp_dir, "shadow_test")
    width, height = (int(v) for v in RESOLUTION.split("x"))
    assert heat.shape == (height, width, 3)
    # shadow_test looks down at a ground plane with black sky above it.
    assert count_color(heat[:5], ground_truth.COLOR_EXCLUDED) == 5 * width
    assert count_color(heat[-5:], ground_truth.COLOR_EXCLUDED) == 0
    assert count_color(heat, ground_truth.COLOR_AGREE_SHADOW) == (
        numbers["cycles_shadowed_pixels"] - numbers["missed_shadow_pixels"])


def _hand_made_scene(scene):
    """A plane, two tall boxes, a sun, a point light and a grey world."""
    bpy.ops.mesh.primitive_plane_add(size=40)
    for x in (-3.0, 3.0):
        bpy.ops.mesh.primitive_cube_add(location=(x, 0.0, 2.0), scale=(0.5, 0.5, 2.0))
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(40), 0.0, np.radians(30)))
    sun = bpy.context.object
    sun.data.angle = np.radians(5.0)
    bpy.ops.object.light_add(type='POINT', location=(0.0, -3.0, 2.0))
    point = bpy.context.object
    bpy.ops.object.camera_add(location=(0.0, -16.0, 9.0), rotation=(np.radians(62), 0, 0))
    scene.camera = bpy.context.object
    world = bpy.data.worlds.new("grey")
    world.color = (0.2, 0.2, 0.2)
    scene.world = world
    return sun, point, world


def test_measure_hides_other_lights_and_restores_the_scene(empty_scene):
    scene = empty_scene
    sun, point, world = _hand_made_scene(scene)
    scene.render.resolution_x, scene.render.resolution_y = 200, 150
    result = ground_truth.measure(scene, 160, 90)
    # The point light and grey world would break on/off = visibility if they were kept.
    assert result.cycles_shadowed_pixels > 100
    assert result.mismatch_percent < 1.0, result.summary()
    assert result.aux_classified_differently == 0
    assert scene.render.engine == "CSM"
    assert (scene.render.resolution_x, scene.render.resolution_y) == (200, 150)
    assert scene.world == world
    assert not point.hide_render and sun.data.use_shadow
    assert abs(sun.data.angle - np.radians(5.0)) < 1e-6
    assert scene.render.image_settings.file_format == 'PNG'


def test_command_reports_user_mistakes_in_one_line(tmp_dir, capsys):
    missing = os.path.join(tmp_dir, "missing.json")
    assert ground_truth.main([missing, "--resolution", "64x64"]) == 3
    assert ground_truth.main([os.path.join(SCENES, "shadow_test.json"),
                              "--resolution", "wide"]) == 2
    assert ground_truth.main([os.path.join(SCENES, "shadow_test.json"), "--resolution",
                              "64x64", "--set", "pcf_radius=lots"]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines()
              if line.startswith("ground truth: error:")]
    assert len(errors) == 3
    assert "missing.json" in errors[0] and "--resolution" in errors[1]
    assert "pcf_radius" in errors[2]

    no_sun = os.path.join(tmp_dir, "no_sun.json")
    with open(os.path.join(SCENES, "shadow_test.json"), encoding="utf-8") as stream:
        description = json.load(stream)
    del description["directional_light"]
    for item in description["objects"]:
        item["mesh"] = os.path.normpath(os.path.join(SCENES, item["mesh"]))
    with open(no_sun, "w", encoding="utf-8") as stream:
        json.dump(description, stream)
    assert ground_truth.main([no_sun, "--resolution", "64x64"]) == 3
    assert "no sun" in capsys.readouterr().err


def test_module_runs_from_the_command_line(tmp_dir):
    """``./dev ground-truth`` (``python -m csm_tools.ground_truth``) on pip bpy, with
    --max-mismatch as exit code."""
    scene = os.path.join(SCENES, "shadow_test.json")
    done = run_module("ground_truth", scene, "--resolution", "240x135", "--set",
                      "depth_bias=0", "--set", "slope_bias=0", "--set", "normal_offset=0",
                      "--max-mismatch", "1", cwd=REPO, timeout=300)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "mismatch:" in done.stdout and "false shadow" in done.stdout
    assert "exceeds 1 %" in done.stderr


def test_alpha_cut_casters_let_light_through_in_cycles_too(empty_scene):
    """A leaf card whose right half is alpha-cut: CSM's masked shadow pass lets the sun
    through the holes, and so must Cycles, or the tool blames CSM for "missed shadow"."""
    from tests.bpy.engine.test_render import _checker_image, _textured_plane
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=30)
    _textured_plane(_checker_image("leaf_card", alpha_holes=True), cutoff=0.5,
                    location=(0, 0, 2.0), size=6.0)
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(20), 0.0, np.radians(10)))
    bpy.ops.object.camera_add(location=(0.0, -14.0, 12.0), rotation=(np.radians(50), 0, 0))
    scene.camera = bpy.context.object
    result = ground_truth.measure(scene, 240, 135)
    assert result.cycles_shadowed_pixels > 200, result.summary()
    assert result.missed_shadow_percent < 2.0, result.summary()
    assert result.mismatch_percent < 3.0, result.summary()
