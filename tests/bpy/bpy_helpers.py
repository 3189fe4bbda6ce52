"""Helpers shared by the in-process bpy tests (imported by name: several test folders have
a conftest.py, so ``from conftest import ...`` would depend on which one loaded last)."""
import os

import bpy
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def render_scene(scene, width=320, height=240):
    """Render with CSM; returns the passes as (H, W, C) float arrays, top row first (as the
    PNG shows it): "combined" RGBA, "aux" (sun visibility, cascade, view depth, coverage),
    "normal". ``LAST_RENDER["plan"]`` holds the cascades used."""
    from csm_engine import engine
    scene.render.resolution_x, scene.render.resolution_y = width, height
    engine.LAST_RENDER["keep_images"] = True
    try:
        bpy.ops.render.render()
    finally:
        engine.LAST_RENDER["keep_images"] = False
    assert engine.LAST_RENDER["error"] is None, engine.LAST_RENDER["error"]
    return {name: image[::-1] for name, image in engine.LAST_RENDER["images"].items()}


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
