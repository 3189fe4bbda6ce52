"""Helpers shared by the in-process bpy tests (imported by name: several test folders have
a conftest.py, so ``from conftest import ...`` would depend on which one loaded last)."""
import bpy
import numpy as np



def render_result(scene, width=320, height=240):
    """Render with CSM; returns the ``RenderResult`` with its passes as (H, W, C) float
    arrays, top row first (as the PNG shows it): "combined" RGBA, "aux" (sun visibility,
    cascade, view depth, coverage), "normal", "position". ``.plan`` holds the cascades used,
    ``.warnings`` what the render said."""
    from csm_engine.blender import engine
    scene.render.resolution_x, scene.render.resolution_y = width, height
    result = engine.render_final(scene, keep_images=True)
    assert result.error is None, result.error
    result.images = {name: image[::-1] for name, image in result.images.items()}
    return result


def render_scene(scene, width=320, height=240):
    """The passes of one CSM render (see ``render_result``)."""
    return render_result(scene, width, height).images


def load_png(path):
    """A PNG as Blender reads it: float32 (H, W, channels) in 0..1, top row first (Blender
    gives RGBA for 8-bit files; no colour management is applied to ``pixels``). The
    numpy-only reader for tools' outputs is ``csm_tools.report_io.read_png``."""
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        width, height = image.size
        channels = image.channels
        pixels = np.empty(width * height * channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(height, width, channels)[::-1]   # Blender's rows run bottom-up
