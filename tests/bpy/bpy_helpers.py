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


def read_png(path):
    """An 8-bit PNG as a (H, W, 3) uint8 array, top row first, read through Blender."""
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * image.channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    rgb = pixels.reshape(height, width, -1)[..., :3]
    return np.round(rgb * 255.0).astype(np.uint8)[::-1]   # Blender's rows run bottom-up
