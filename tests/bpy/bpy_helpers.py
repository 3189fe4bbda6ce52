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


def cube_on_plane(scene):
    """A 12 m ground plane, a 2 m cube standing 0.2 m above it, a sun (35, 25 degrees) and
    the scene camera looking down at both from (7, -7, 5). Returns (cube, sun)."""
    bpy.ops.mesh.primitive_plane_add(size=12)
    bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1.2))
    cube = bpy.context.object
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(35), np.radians(25), 0))
    sun = bpy.context.object
    bpy.ops.object.camera_add(location=(7, -7, 5), rotation=(np.radians(63), 0, np.radians(45)))
    scene.camera = bpy.context.object
    return cube, sun


def render_scene(scene, width=320, height=240):
    """The passes of one CSM render (see ``render_result``)."""
    return render_result(scene, width, height).images


def viewport_frame(scene, renderer, cache, width, height):
    """One viewport redraw of the scene camera's view, as ``view_draw`` draws it (no FXAA):
    a snapshot, ``cache`` synced, ``renderer.draw_viewport`` into an offscreen float
    target; returns its RGBA pixels (height, width, 4), bottom row first."""
    import gpu
    from csm_engine.blender import snapshot
    depsgraph = bpy.context.evaluated_depsgraph_get()
    camera = snapshot.camera_from_scene(scene, depsgraph, width, height)
    snap = snapshot.take(depsgraph, camera, is_viewport=True)
    cache.sync(snap.mesh_sources)
    snap.mesh_sources = {}
    offscreen = gpu.types.GPUOffScreen(width, height, format='RGBA32F')
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0, 0, 0, 0))
            renderer.draw_viewport(snap, cache, width, height, fxaa=False)
            buffer = gpu.types.Buffer('FLOAT', width * height * 4)
            fb.read_color(0, 0, width, height, 4, 0, 'FLOAT', data=buffer)
    finally:
        offscreen.free()
    return np.frombuffer(buffer, np.float32).reshape(height, width, 4).copy()


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


class RecordingLayout:
    """Stands in for bpy.types.UILayout (which needs a window): records the labels,
    properties and operators a panel's draw() puts in it."""

    def __init__(self, root=None):
        self.root = root or self
        if root is None:
            self.labels, self.props, self.operators = [], [], []

    def _child(self, *args, **kwargs):
        return RecordingLayout(self.root)
    column = row = box = split = _child

    def separator(self, *args, **kwargs):
        pass

    def label(self, text="", **kwargs):
        self.root.labels.append(text)

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, name
        self.root.props.append(name)

    def operator(self, idname, **kwargs):
        self.root.operators.append(idname)


def pipeline_drawing(plan):
    """A new pipeline (its own textures, records and planning state) that draws ``plan``
    instead of planning. It is the reference for a kept frame: the same cascades drawn
    with nothing kept, whatever the planner carried over from the views the kept frame's
    pipeline drew before (a new view's plan may differ)."""
    from csm_engine.render import pipeline

    class DrawsWithPlan(pipeline.Pipeline):
        def _plan(self, snap, bounds, depth_blocks=None, gbuffer_only=False):
            return plan

    return DrawsWithPlan()
