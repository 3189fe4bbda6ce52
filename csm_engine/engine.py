"""The ``CSM`` RenderEngine: thin adapters from Blender's engine API to the pipeline.

Owns nothing but the glue: ``render()`` (F12, ``blender -b -f``, the CLI) and
``view_update()``/``view_draw()`` (the 3D viewport in Rendered mode) gather a snapshot, keep
the mesh cache in sync, call ``Pipeline`` and hand the pixels to Blender. GPU objects live
on the engine instance, created lazily in the context that draws them, and are dropped when
Blender frees the instance.
"""

import bpy
import numpy as np

from . import mesh_cache, pipeline, shaders, snapshot

# The last error a final render hit (None when it succeeded); the CLI reads it because
# RenderEngine.report() does not reach a caller in background mode.
# Tests set "keep_images" to also get the passes as numpy arrays (top row last, like GL).
LAST_RENDER = {"error": None, "warnings": [], "timings": {}, "keep_images": False,
               "images": None, "plan": None}

# Render targets and shadow atlas kept from one final render to the next (each render gets
# a new engine instance and GPU context; textures, unlike framebuffers, may be shared).
_FINAL_RENDER_TEXTURES = {}


def _wants_normal_pass(depsgraph):
    layer = depsgraph.view_layer
    return bool(getattr(layer, "use_pass_normal", False))


def _write_pass(render_pass, pixels):
    """Copy an (H, W, C) float32 array into a RenderResult pass (3.4 .. 5.x)."""
    flat = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1, render_pass.channels)
    try:
        render_pass.rect.foreach_set(flat.ravel())
    except (TypeError, RuntimeError, ValueError):
        # 3.4 wants W*H rows of channels rather than one flat array.
        render_pass.rect.foreach_set(flat)


class CSMRenderEngine(bpy.types.RenderEngine):
    bl_idname = "CSM"
    bl_label = "CSM"
    bl_use_preview = False
    bl_use_gpu_context = True
    bl_use_shading_nodes_custom = False
    # Material Preview stays EEVEE's; only Rendered shading runs CSM.
    bl_use_eevee_viewport = True

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.pipeline = None
        self.cache = None

    def __del__(self):
        # Drop GPU objects while the engine's context is still known to Blender.
        try:
            self.pipeline = None
            self.cache = None
        except (AttributeError, ReferenceError):
            pass

    # -- final render ----------------------------------------------------------------------
    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", 'COLOR')
        if renderlayer.use_pass_z:
            self.register_pass(scene, renderlayer, "Depth", 1, "Z", 'VALUE')
        if renderlayer.use_pass_normal:
            self.register_pass(scene, renderlayer, "Normal", 3, "XYZ", 'VECTOR')
        self.register_pass(scene, renderlayer, "Shadow", 1, "X", 'VALUE')
        self.register_pass(scene, renderlayer, "Cascade", 1, "X", 'VALUE')

    def render(self, depsgraph):
        LAST_RENDER.update(error=None, warnings=[], timings={}, images=None, plan=None)
        scene = depsgraph.scene
        scale = scene.render.resolution_percentage / 100.0
        width = max(int(scene.render.resolution_x * scale), 1)
        height = max(int(scene.render.resolution_y * scale), 1)
        camera = snapshot.camera_from_scene(scene, depsgraph, width, height)
        if camera is None:
            self._fail("the scene has no camera: add one or set Scene > Camera")
            return
        self.update_stats("CSM", "Reading scene")
        snap = snapshot.take(depsgraph, camera)
        cache = mesh_cache.MeshCache()
        cache.sync(snap.mesh_sources)
        snap.mesh_sources = {}
        self.update_progress(0.3)
        self.update_stats("CSM", f"Drawing {sum(m.triangle_count for m in cache.meshes.values())}"
                                 " triangles")
        renderer = pipeline.Pipeline(textures=_FINAL_RENDER_TEXTURES)
        try:
            images, plan = renderer.render_offscreen(
                snap, cache, with_positions=LAST_RENDER["keep_images"],
                with_normals=LAST_RENDER["keep_images"] or _wants_normal_pass(depsgraph))
        except shaders.ShaderCompileError as error:
            self._fail(str(error))
            return
        self.update_progress(0.9)

        result = self.begin_result(0, 0, width, height)
        for name in ("Shadow", "Cascade"):
            if result.layers[0].passes.find_by_name(name, "") is None:
                try:
                    self.add_pass(name, 1, "X")
                except Exception:
                    pass
        passes = result.layers[0].passes
        aux = images["aux"]
        _write_pass(passes["Combined"], images["combined"])
        pass_pixels = {"Depth": aux[..., 2:3], "Shadow": aux[..., 0:1],
                       "Cascade": aux[..., 1:2]}
        if "normal" in images:       # read back only when the Normal pass is on
            pass_pixels["Normal"] = images["normal"][..., :3]
        for name, pixels in pass_pixels.items():
            render_pass = passes.find_by_name(name, "")
            if render_pass is not None:
                _write_pass(render_pass, pixels)
        self.end_result(result)
        for warning in renderer.warnings:
            self.report({'WARNING'}, "CSM: " + warning)
        LAST_RENDER.update(warnings=list(renderer.warnings), timings=dict(renderer.timings))
        if LAST_RENDER["keep_images"]:
            LAST_RENDER.update(images=images, plan=plan)
        self.update_progress(1.0)

    def _fail(self, message):
        LAST_RENDER["error"] = message
        self.report({'ERROR'}, "CSM: " + message)

    # -- viewport ------------------------------------------------------------------------
    def view_update(self, context, depsgraph):
        if self.cache is None:
            self.cache = mesh_cache.MeshCache()
        apply_depsgraph_updates(self.cache, depsgraph.updates)

    def view_draw(self, context, depsgraph):
        import gpu
        if self.cache is None:
            self.cache = mesh_cache.MeshCache()
        if self.pipeline is None:
            self.pipeline = pipeline.Pipeline()
        region = context.region
        camera = snapshot.camera_from_region(context.region_data, region.width, region.height)
        snap = snapshot.take(depsgraph, camera, is_viewport=True)
        self.cache.sync(snap.mesh_sources)
        snap.mesh_sources = {}
        gpu.state.blend_set('ALPHA_PREMULT' if snap.film_transparent else 'NONE')
        try:
            self.pipeline.draw(snap, self.cache, None, region.width, region.height)
        except shaders.ShaderCompileError as error:
            # First compile failed: nothing good to fall back to. Say so once per draw.
            print(f"CSM: {error}")
        finally:
            gpu.state.blend_set('NONE')
            gpu.state.depth_test_set('NONE')
            gpu.state.depth_mask_set(False)


def apply_depsgraph_updates(cache, updates):
    """Turn depsgraph updates into cache invalidations (geometry only; moves upload nothing)."""
    dirty = set()
    materials = False
    for update in updates:
        datablock = update.id
        if isinstance(datablock, bpy.types.Object):
            if update.is_updated_geometry:
                original = datablock.original if datablock.original else datablock
                dirty.add(original.name)
        elif isinstance(datablock, (bpy.types.Material, bpy.types.NodeTree)):
            materials = True
        elif isinstance(datablock, bpy.types.Image):
            cache.textures.pop(datablock.name, None)
    if dirty or materials:
        cache.invalidate(dirty, materials=materials)


def _compatible_panels():
    """Blender's own panels that apply to any engine (dimensions, output, colour management,
    camera, light, world): those that list BLENDER_RENDER, plus EEVEE's light panels."""
    wanted_eevee = {"DATA_PT_EEVEE_light", "DATA_PT_EEVEE_light_distance", "DATA_PT_spot",
                    "DATA_PT_EEVEE_shadow", "EEVEE_WORLD_PT_surface", "DATA_PT_light",
                    "RENDER_PT_eevee_film", "EEVEE_MATERIAL_PT_surface",
                    "EEVEE_MATERIAL_PT_context_material"}
    excluded = {"VIEWLAYER_PT_filter", "VIEWLAYER_PT_layer_passes"}
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if engines is None or panel.__name__ in excluded or "lightprobe" in panel.__name__:
            continue
        if "BLENDER_RENDER" in engines or panel.__name__ in wanted_eevee:
            yield panel


def register():
    bpy.utils.register_class(CSMRenderEngine)
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.add("CSM")


def unregister():
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.discard("CSM")
    bpy.utils.unregister_class(CSMRenderEngine)
