"""A frame that cannot be drawn as asked says so: impossible settings are clamped with a
warning, an impossible camera range still renders, and anything that stops a render is one
line in the result with no image behind it."""
import bpy
import numpy as np
import pytest

from csm_engine.blender import engine
from csm_engine.render import pipeline
from tests.bpy.bpy_helpers import render_result
from tests.bpy.scenes import add_box, add_camera, add_ground, add_sun


@pytest.fixture
def box_on_ground(empty_scene):
    add_ground(20)
    add_box((0, 0, 1), (1, 1, 1))
    add_sun((0.3, 0.2, -1.0))
    add_camera(empty_scene, (12, -12, 9), (0, 0, 0))
    return empty_scene


def _shadowed_fraction(result):
    aux = result.images["aux"]
    covered = aux[..., 3] > 0.5
    return float(((aux[..., 0] < 0.5) & covered).sum() / max(covered.sum(), 1))


@pytest.mark.parametrize("name, value, used, words", [
    ("cascade_count", 99, 4, ["cascade_count", "99", "1..4"]),
    ("resolution", 1, 64, ["resolution", "64"]),
    ("blend_band", -5.0, 0.0, ["blend_band", "-5"]),
    ("pcf_radius", -3, 0, ["pcf_radius", "-3"]),
])
def test_settings_forced_past_their_limits_are_clamped_and_named(box_on_ground, name, value,
                                                                  used, words):
    box_on_ground.csm[name] = value            # ID-property access bypasses the UI limits
    assert getattr(box_on_ground.csm, name) == value
    result = render_result(box_on_ground, 160, 120)
    warning = next((w for w in result.warnings if name in w), None)
    assert warning is not None, result.warnings
    for word in words:
        assert word in warning, (word, warning)
    assert _shadowed_fraction(result) > 0.01, "the box still casts its shadow"
    if name == "cascade_count":
        assert result.plan.cascade_count == used
    if name == "resolution":
        assert result.plan.tiles[0].resolution == used


def test_warnings_show_values_without_float32_noise(box_on_ground):
    box_on_ground.csm.split_scheme = 'MANUAL'
    box_on_ground.csm.manual_splits = (0.5, 0.2, 0.6)
    box_on_ground.csm.shadow_distance = 40.0
    result = render_result(box_on_ground, 96, 64)
    text = " ".join(result.warnings)
    assert "manual split" in text, text
    assert "0000000" not in text and "9999999" not in text, text


def test_a_camera_range_float32_cannot_hold_still_renders_with_shadows(box_on_ground):
    camera = box_on_ground.camera.data
    camera.clip_start = 1e-4
    camera.clip_end = 1e5                      # far / near = 1e9
    result = render_result(box_on_ground, 160, 120)
    assert result.error is None
    assert _shadowed_fraction(result) > 0.01


def test_any_exception_in_a_render_is_one_line_and_no_image(box_on_ground, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("the GPU\nfell over")
    monkeypatch.setattr(pipeline.Pipeline, "draw", broken)
    box_on_ground.render.resolution_x, box_on_ground.render.resolution_y = 64, 48
    result = engine.render_final(box_on_ground, keep_images=True)
    assert result.error == "RuntimeError: the GPU fell over"
    assert result.images is None
    image = bpy.data.images.get("Render Result")
    pixels = np.zeros(4 * 64 * 48, dtype=np.float32)
    if image is not None and image.has_data:
        image.pixels.foreach_get(pixels[:len(image.pixels)])
    assert not pixels.any(), "nothing was handed to Blender as the frame"


def test_render_targets_that_cannot_be_allocated_are_named(box_on_ground, monkeypatch):
    import gpu

    class NoMemory:
        def __init__(self, size, format):
            raise MemoryError("GPUTexture: texture alloc failed")
    renderer = pipeline.Pipeline()
    monkeypatch.setattr(gpu.types, "GPUTexture", NoMemory)
    with pytest.raises(pipeline.RenderTargetError) as failure:
        renderer.targets.texture("albedo", (16384, 16384), 'RGBA16F')
    message = str(failure.value)
    assert "16384x16384" in message and "albedo" in message and "2,048 MB" in message
    assert engine.failure_message(failure.value) == message


def test_more_point_lights_than_the_shader_draws_are_counted_in_a_warning(box_on_ground):
    for index in range(70):
        bpy.ops.object.light_add(type='POINT', location=(index % 10 - 5, index // 10 - 3, 3))
    result = render_result(box_on_ground, 64, 48)
    assert any("70 point lights" in w and "6 are left out" in w for w in result.warnings), \
        result.warnings


def test_the_viewport_message_is_drawn_over_a_cleared_frame(box_on_ground):
    import gpu
    render_result(box_on_ground, 16, 16)       # a GPU context exists after a render
    offscreen = gpu.types.GPUOffScreen(320, 80)
    with offscreen.bind():
        framebuffer = gpu.state.active_framebuffer_get()
        framebuffer.clear(color=(1.0, 1.0, 1.0, 1.0))
        engine.draw_message(320, 80, "CSM cannot draw this view: something is wrong " * 3)
        pixels = np.array(framebuffer.read_color(0, 0, 320, 80, 4, 0, 'FLOAT').to_list())
    offscreen.free()
    rgb = pixels.reshape(80, 320, 4)[..., :3]
    background = np.all(np.abs(rgb - 0.12) < 0.02, axis=-1)
    text = (rgb[..., 0] > 0.5) & (rgb[..., 2] < rgb[..., 0])
    assert background.mean() > 0.6, "the old frame is cleared to dark grey"
    assert text.sum() > 100, "the reason is written in red"
    assert text[:, 160:].any(), "long messages wrap instead of running off the right"
