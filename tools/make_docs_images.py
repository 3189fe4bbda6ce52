"""Render the pictures in docs/images/ (the README's default scene, every debug view, the
split schemes side by side). Run on pip bpy (after ./dev setup), from any folder:

    .venv/bin/python tools/make_docs_images.py [--resolution 960x540]

The session is set up by ``cli.open_scene`` as for ``./dev render``: the same bundled scene,
size and Standard view transform.
"""
import argparse
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
OUT = os.path.join(REPO, "docs", "images")

DEBUG_VIEWS = ("CASCADES", "SHADOW_FACTOR", "SHADOW_MAP", "TEXEL_DENSITY", "ALBEDO", "NORMAL",
               "POSITION", "DEPTH", "SPECULAR")
SCHEMES = (("UNIFORM", {}), ("LOG", {}), ("HYBRID", {}),
           ("MANUAL", {"manual_splits": (0.05, 0.2, 0.6)}))


def render(scene, path, **settings):
    """Render ``scene`` with CSM ``settings`` changed for this one picture; write ``path``."""
    from csm_engine.blender import engine
    saved = {name: getattr(scene.csm, name) for name in settings}
    for name, value in settings.items():
        setattr(scene.csm, name, value)
    scene.render.filepath = path
    try:
        result = engine.render_final(scene, write_still=True)
    finally:
        for name, value in saved.items():
            setattr(scene.csm, name, value)
    if result.error:
        sys.exit(f"make_docs_images: {os.path.basename(path)}: render failed: {result.error}")
    print("wrote", os.path.relpath(path, REPO))


def side_by_side(paths, out):
    """Join PNGs left to right with Blender's image API (no extra dependencies)."""
    import bpy
    images = [bpy.data.images.load(p, check_existing=False) for p in paths]
    width, height = images[0].size
    canvas = np.zeros((height, width * len(images), 4), dtype=np.float32)
    for i, image in enumerate(images):
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        canvas[:, i * width:(i + 1) * width] = pixels.reshape(height, width, 4)
        canvas[:, i * width:i * width + 2] = (1, 1, 1, 1)      # a thin white divider
        bpy.data.images.remove(image)
    joined = bpy.data.images.new("joined", width * len(paths), height, alpha=True)
    joined.pixels.foreach_set(canvas.ravel())
    joined.filepath_raw = out
    joined.file_format = 'PNG'
    joined.save()
    bpy.data.images.remove(joined)
    print("wrote", os.path.relpath(out, REPO))


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--resolution", default="960x540", metavar="WxH")
    args = parser.parse_args()
    from csm_engine.blender import cli
    try:
        scene = cli.open_scene("default", resolution=cli.parse_resolution(args.resolution))
    except cli.CLIError as error:
        sys.exit(f"make_docs_images: error: {error}")
    scene.render.engine = "CSM"
    scene.render.image_settings.file_format = 'PNG'
    os.makedirs(OUT, exist_ok=True)

    render(scene, os.path.join(OUT, "default_scene.png"))
    for view in DEBUG_VIEWS:
        render(scene, os.path.join(OUT, f"debug_{view.lower()}.png"), debug_view=view)
    # Cascade 0 covers the first metres, empty in this view; show the far cascade.
    render(scene, os.path.join(OUT, "debug_shadow_map.png"), debug_view="SHADOW_MAP",
           debug_shadow_map=2)
    render(scene, os.path.join(OUT, "debug_shadow_map_inset.png"), debug_inset=True,
           debug_shadow_map=2)

    # Split schemes from a camera that sees near and far content, so all cascades show.
    camera = scene.camera
    saved = camera.matrix_world.copy()
    from mathutils import Vector
    camera.location = (-150.0, -150.0, 60.0)
    camera.rotation_euler = (Vector((60.0, 60.0, 0.0)) - camera.location).to_track_quat(
        '-Z', 'Y').to_euler()
    paths_ = []
    for scheme, extra in SCHEMES:
        path = os.path.join(OUT, f"split_{scheme.lower()}.png")
        render(scene, path, debug_view="CASCADES", split_scheme=scheme, **extra)
        paths_.append(path)
    side_by_side(paths_, os.path.join(OUT, "split_schemes.png"))
    for path in paths_:
        os.remove(path)
    camera.matrix_world = saved


if __name__ == "__main__":
    main()
