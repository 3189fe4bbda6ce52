"""The ``CSM`` RenderEngine: thin adapters from Blender's engine API to the pipeline.

Owns nothing but the glue: ``render()`` (F12, ``blender -b -f``, the CLI) and
``view_update()``/``view_draw()`` (the 3D viewport in Rendered mode) gather a snapshot, keep
the mesh cache in sync, call ``Pipeline`` and hand the pixels to Blender. Over a viewport
frame in the Cascades view, ``draw_cascade_legend`` adds the legend (its text is
Blender's ``blf``, so it is written here; ``render/overlays.py`` lays it out). GPU objects
live on the engine instance, created lazily in the context that draws them, and are
dropped when Blender frees the instance.

``render_final(scene)`` is the one way code asks for a final render and gets its
``RenderResult`` back (images, plan, timings, warnings, error): Blender creates the engine
itself, so the request travels to ``render()`` for the duration of that one call.
"""

import atexit
import contextlib
import dataclasses
import math
import time

import bpy

from ..core.view_state import ShadowViewState
from ..render import gpu_mesh, overlays, pipeline, shaders
from ..render.readback import ReadbackMemory
from ..render.resources import RenderResources
from ..render.result import RenderResult
from . import compat, mesh_cache, render_passes, snapshot

# Render targets and shadow atlas kept from one final render to the next, with the record
# of what they hold (each render gets a new engine instance and GPU context; textures,
# unlike framebuffers, may be shared), so an unchanged pass is not drawn again.
_FINAL_RENDER_RESOURCES = RenderResources()
# What shadow planning carries from one final render to the next (Freeze Cascades holds
# the first render's cascades): the final render is one view, each viewport another.
_FINAL_RENDER_VIEW = ShadowViewState()
# GPU meshes kept from one final render to the next, so a re-render, or an animation frame,
# uploads only meshes whose contents changed (MeshCache.check_contents). Vertex and index
# buffers may be shared between GPU contexts; a GPUBatch's vertex arrays (VAOs) are per
# context, and Blender's GL backend rebuilds them when a batch is drawn in a new context
# and frees the old ones through their own context (gl_batch.cc, GLVaoCache::context_check).
# Meshes the scene no longer uses are dropped inside the next render (MeshCache.sync).
_FINAL_RENDER_MESHES = []
# Read-back buffers and the contiguous pass copies handed to Blender, kept from one final
# render to the next (render/readback.py: fresh blocks that size cost page faults each
# frame); used when the caller does not keep the images.
_FINAL_RENDER_MEMORY = ReadbackMemory()


class _Request:
    """What the caller of ``render_final`` asked for, and what ``render()`` produced."""

    def __init__(self, keep_images=False, profile=False):
        self.keep_images = keep_images
        self.profile = profile
        self.result = None


# The request of the ``render_final`` call in progress (None: a render the user started).
_ACTIVE_REQUEST = [None]


@contextlib.contextmanager
def _requested(request):
    previous = _ACTIVE_REQUEST[0]
    _ACTIVE_REQUEST[0] = request
    try:
        yield request
    finally:
        _ACTIVE_REQUEST[0] = previous


def render_final(scene, write_still=False, keep_images=False, profile=False):
    """Render ``scene`` with its own engine setting, as F12 does, and return the
    ``RenderResult`` (for another engine, one with only the wall time). ``keep_images``
    also returns the passes as numpy arrays (and world positions, which tests ray-cast
    from); ``profile`` waits for the GPU after each pass so its time is its own."""
    request = _Request(keep_images=keep_images, profile=profile)
    start = time.perf_counter()
    with _requested(request):
        if scene != bpy.context.scene:
            raise ValueError(f"render_final renders the context's scene, not '{scene.name}'")
        try:
            bpy.ops.render.render(write_still=write_still)
        except RuntimeError:
            # The operator raises on the engine's own ERROR report, which is in the result.
            if request.result is None or request.result.error is None:
                raise
    result = request.result
    if result is None:
        result = RenderResult()
        if scene.render.engine == CSMRenderEngine.bl_idname:
            result.error = "the render stopped before producing an image"
    result.timings["wall"] = time.perf_counter() - start
    return result


_FORGET_FINAL_MESHES = [False]


def forget_final_render_meshes():
    """Make the next final render read and upload every mesh again, as the first render
    of a session does (the benchmark's "first render"). The meshes are dropped inside
    that render, in the context that draws."""
    _FORGET_FINAL_MESHES[0] = True


def forget_final_render_passes():
    """Make the next final render draw every pass again (shadow maps, G-buffer, AO), as
    one whose view and scene changed does; its meshes are kept (the benchmark's full
    frames)."""
    _FINAL_RENDER_RESOURCES.frame_cache.forget()


def forget_final_render_view():
    """Make the next final render plan its shadows as the first render of a session
    does: nothing frozen by Freeze Cascades, nothing held from an earlier render (the
    farm calls it when a worker opens another file)."""
    _FINAL_RENDER_VIEW.__init__()


def _final_mesh_cache():
    if not _FINAL_RENDER_MESHES:
        _FINAL_RENDER_MESHES.append(mesh_cache.MeshCache(check_contents=True, realize=False))
    return _FINAL_RENDER_MESHES[0]


def _simplify(scene):
    """The Simplify settings that change what modifiers make in a final render."""
    render = scene.render
    return (bool(getattr(render, "use_simplify", False)),
            getattr(render, "simplify_subdivision_render", None))


def _reads(wanted, keep_images):
    """What the final render reads back: Combined always; the aux target (Shadow, Cascade,
    then Depth) with as many channels as the enabled passes use; normals only for the
    Normal pass (the other passes add their own reads: ``Pipeline.render_offscreen``).
    ``keep_images`` reads every channel (tests look at all of them)."""
    if keep_images:
        return {"combined": 4, "aux": 4, "normal": 4}
    reads = {"combined": 4, "aux": 3 if "Depth" in wanted.names else 2}
    if "Normal" in wanted.names:
        reads["normal"] = 3
    return reads


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
        self.snapshots = ViewportSnapshots()

    def __del__(self):
        # Drop GPU objects while the engine's context is still known to Blender.
        try:
            self.pipeline = None
            self.cache = None
        except (AttributeError, ReferenceError):
            pass

    # -- final render ----------------------------------------------------------------------
    def update_render_passes(self, scene=None, renderlayer=None):
        render_passes.register(self, scene, renderlayer)

    def render(self, depsgraph):
        request = _ACTIVE_REQUEST[0] or _Request()
        try:
            request.result = self._render(depsgraph, request)
        except Exception as error:
            # Whatever stopped the frame (an impossible camera, a GPU allocation, a bug), the
            # user gets one line and no image; a black image with a success message is worse.
            request.result = RenderResult(error=failure_message(error))
        if request.result.error:
            self.report({'ERROR'}, "CSM: " + request.result.error)
        for warning in request.result.warnings:
            self.report({'WARNING'}, "CSM: " + warning)
        if request.result.shadow_error is not None:
            self.report({'INFO'}, "CSM: Shadow error: " + request.result.shadow_error.label)

    def _stats(self, text):
        # In background mode Blender prints every stats line ("Fra:1 Mem:..."); there the
        # terminal is the user's and the command line says what happened itself.
        if not bpy.app.background:
            self.update_stats("CSM", text)

    def _render(self, depsgraph, request):
        scene = depsgraph.scene
        scale = scene.render.resolution_percentage / 100.0
        width = max(int(scene.render.resolution_x * scale), 1)
        height = max(int(scene.render.resolution_y * scale), 1)
        camera = snapshot.camera_from_scene(scene, depsgraph, width, height)
        if camera is None:
            return RenderResult(error="the scene has no camera: add one or set Scene > Camera")
        self._stats("Reading scene")
        start = time.perf_counter()
        snap = snapshot.take(depsgraph, camera)
        scene_read = time.perf_counter() - start
        mark = gpu_mesh.serial_mark()
        cache = _final_mesh_cache()
        if _FORGET_FINAL_MESHES[0]:
            cache.clear()
            _FORGET_FINAL_MESHES[0] = False
        cache.sync(snap.mesh_sources, _simplify(scene))
        snap.mesh_sources = {}
        mesh_upload = time.perf_counter() - start - scene_read
        self.update_progress(0.3)
        self._stats(f"Drawing {sum(m.triangle_count for m in cache.meshes.values())} triangles")
        renderer = pipeline.Pipeline(resources=_FINAL_RENDER_RESOURCES,
                                     view_state=_FINAL_RENDER_VIEW)
        renderer.profile = request.profile
        wanted = render_passes.request(depsgraph.view_layer, scene.world)
        memory = None if request.keep_images else _FINAL_RENDER_MEMORY
        result = renderer.render_offscreen(snap, cache, _reads(wanted, request.keep_images),
                                           with_positions=request.keep_images, passes=wanted,
                                           memory=memory)
        result.timings.update(scene_read=scene_read, mesh_upload=mesh_upload)
        result.mesh_uploads, result.upload_bytes = gpu_mesh.uploads_since(
            cache.meshes.values(), mark)
        self.update_progress(0.9)

        t = time.perf_counter()
        # Render Region: the whole camera view was drawn (so the region's shadows and
        # pixels are those of the full render); Blender's result holds only the region, and
        # Blender itself pastes it into the full frame unless Crop to Render Region is on.
        x0, y0, x1, y1 = render_region(scene.render, width, height)
        region_images = {name: image[y0:y1, x0:x1] for name, image in result.images.items()}
        # Blender calls render() once per view layer: this one's passes go to its own layer.
        render_result = self.begin_result(0, 0, x1 - x0, y1 - y0,
                                          layer=depsgraph.view_layer.name)
        combined = region_images["combined"]
        if memory is not None:
            combined = memory.contiguous("Combined", combined)
        compat.write_pass(render_result.layers[0].passes["Combined"], combined)
        aux = region_images["aux"]
        region_images.update(Shadow=aux[..., 0:1], Cascade=aux[..., 1:2])
        render_passes.write(self, render_result, region_images, wanted, result.metadata,
                            memory)
        self.end_result(render_result)
        result.timings["handoff"] = time.perf_counter() - t
        if not request.keep_images:
            result.images = None
        self.update_progress(1.0)
        return result

    # -- viewport ------------------------------------------------------------------------
    def view_update(self, context, depsgraph):
        if self.cache is None:
            self.cache = mesh_cache.MeshCache()
        self.snapshots.scene_updated(self.cache, depsgraph.updates)
        # Blender redraws the viewport after an update only when a notifier asks for it;
        # an ID tagged with no notifier (a script's update_tag(), which Blender asks for
        # after setting an add-on's property such as object.cycles) left the last frame on
        # screen (measured in 3.4: no draw within 10 s).
        self.tag_redraw()

    def view_draw(self, context, depsgraph):
        import gpu
        region = context.region
        try:
            if self.cache is None:
                self.cache = mesh_cache.MeshCache()
            if self.pipeline is None:
                self.pipeline = pipeline.Pipeline()
            camera = snapshot.camera_from_region(context.region_data, region.width,
                                                 region.height)
            snap = self.snapshots.frame(depsgraph, camera, self.cache)
            gpu.state.blend_set('ALPHA_PREMULT' if snap.film_transparent else 'NONE')
            plan = self.pipeline.draw_viewport(snap, self.cache, region.width,
                                               region.height, fxaa=bool(snap.settings.fxaa))
            rows = overlays.legend_rows(snap, plan, self.pipeline.shadow_error)
            if rows:
                draw_cascade_legend(snap, plan, region.width, region.height,
                                    *legend_room(context), context.preferences.system.ui_scale,
                                    rows=rows)
            self._viewport_error = None
        except Exception as error:
            # The viewport shows the reason instead of a stale or half-drawn frame; the
            # console gets it once, not at every redraw.
            message = failure_message(error)
            if message != getattr(self, "_viewport_error", None):
                print(f"CSM: viewport: {message}")
                self._viewport_error = message
            draw_message(region.width, region.height, "CSM cannot draw this view: " + message)
        finally:
            gpu.state.blend_set('NONE')
            gpu.state.depth_test_set('NONE')
            gpu.state.depth_mask_set(False)


class ViewportSnapshots:
    """The viewport's frame snapshot between redraws.

    Blender calls ``view_update`` after every depsgraph update (an object, light,
    material, World or CSM setting edited, the frame changed, undo) before the next
    ``view_draw``; ``scene_changed`` records it. A redraw with no update since the last
    one (orbit, pan, zoom, a resized region) draws the last snapshot with the new view and
    reads nothing from Blender: no pass over every object and its matrix."""

    def __init__(self):
        self.snap = None
        self.scene_changed = True
        self._time = None
        self.mesh_uploads = 0       # meshes this viewport's syncs uploaded, all told

    def scene_updated(self, cache, updates):
        """What ``view_update`` does with the depsgraph's updates: invalidate what they
        touch in ``cache``, and read the scene again at the next redraw."""
        apply_depsgraph_updates(cache, updates)
        self.scene_changed = True

    def frame(self, depsgraph, camera, cache):
        """This redraw's snapshot; ``cache`` is synced when the scene was read again. A
        new frame number reads it again too, whatever ``view_update`` said."""
        scene = depsgraph.scene
        time = (scene.frame_current, scene.frame_subframe)
        if self.snap is None or self.scene_changed or time != self._time:
            snap = snapshot.take(depsgraph, camera, is_viewport=True)
            cache.sync(snap.mesh_sources)
            self.mesh_uploads += cache.last_sync["uploaded"]
            snap.mesh_sources = {}
            self.snap, self.scene_changed, self._time = snap, False, time
            return snap
        return dataclasses.replace(self.snap, camera=camera)


def render_region(render, width, height):
    """The pixels (x0, y0, x1, y1), bottom-left origin, that a final render delivers:
    Output > Render Region when it is on, else the whole image. Rounded as Blender rounds
    it (render_init_from_main: truncation of border * size), so the result is the size
    Blender allocated."""
    if not render.use_border:
        return 0, 0, width, height
    x0, x1 = int(render.border_min_x * width), int(render.border_max_x * width)
    y0, y1 = int(render.border_min_y * height), int(render.border_max_y * height)
    if x1 <= x0 or y1 <= y0:    # Blender renders the whole image for an empty region
        return 0, 0, width, height
    return x0, y0, x1, y1


def failure_message(error):
    """One line for the user about an exception that stopped a frame. Set CSM_DEBUG=1 to
    also print the traceback (for reporting a bug)."""
    import os
    if os.environ.get("CSM_DEBUG"):
        import traceback
        traceback.print_exception(type(error), error, error.__traceback__)
    if isinstance(error, shaders.ShaderCompileError):
        return str(error)
    if isinstance(error, MemoryError):
        return "out of memory (try a smaller resolution or shadow-map size)"
    text = " ".join(str(error).split()) or type(error).__name__
    return text if isinstance(error, (ValueError, pipeline.RenderTargetError)) \
        else f"{type(error).__name__}: {text}"


def draw_message(width, height, text):
    """Clear the viewport to dark grey and write ``text`` on it (wrapped to the width)."""
    import blf
    import gpu
    framebuffer = gpu.state.active_framebuffer_get()
    framebuffer.clear(color=(0.12, 0.12, 0.12, 1.0))
    font, size = 0, 14
    compat.blf_size(font, size)
    blf.color(font, 1.0, 0.45, 0.35, 1.0)
    words, lines, line = text.split(), [], ""
    for word in words:
        candidate = f"{line} {word}".strip()
        if line and blf.dimensions(font, candidate)[0] > width - 40:
            lines.append(line)
            line = word
        else:
            line = candidate
    lines.append(line)
    from mathutils import Matrix
    pixel_space = Matrix(((2.0 / width, 0, 0, -1), (0, 2.0 / height, 0, -1), (0, 0, -1, 0),
                          (0, 0, 0, 1)))
    with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
        gpu.matrix.load_identity()
        gpu.matrix.load_projection_matrix(pixel_space)
        y = height - 40
        for line in lines:
            blf.position(font, 20, y, 0)
            blf.draw(font, line)
            y -= int(size * 1.6)


def visible_corner(area, region):
    """The bottom-left corner, in ``region``'s pixels, of the part of the viewport that
    Blender's other regions leave uncovered: with Region Overlap the toolbar (and a header,
    asset shelf or last-operation panel at the bottom) is drawn over the viewport."""
    left = bottom = 0
    if area is None:
        return left, bottom
    for other in area.regions:
        if other.type == 'WINDOW' or other.width <= 1 or other.height <= 1:
            continue
        right_edge = other.x + other.width - region.x
        top_edge = other.y + other.height - region.y
        overlaps = (right_edge > 0 and other.x < region.x + region.width and top_edge > 0
                    and other.y < region.y + region.height)
        if not overlaps:
            continue
        if other.x <= region.x and other.height > region.height // 2:
            left = max(left, right_edge)           # a full-height strip on the left
        elif other.y <= region.y and other.x < region.x + region.width // 2:
            bottom = max(bottom, top_edge)         # along the bottom, reaching the left half
    return left, bottom


def camera_frame_corner(scene, region, region_3d):
    """Looking through the scene camera, the bottom-left corner of its frame in
    ``region``'s pixels (Blender dims what lies outside it); else (0, 0). A frame corner
    beyond the region's middle (zoomed far in or panned away) is ignored."""
    camera = scene.camera if scene is not None else None
    if camera is None or region_3d is None or region_3d.view_perspective != 'CAMERA':
        return 0, 0
    from bpy_extras.view3d_utils import location_3d_to_region_2d
    points = [location_3d_to_region_2d(region, region_3d, camera.matrix_world @ corner)
              for corner in camera.data.view_frame(scene=scene)]
    if any(point is None for point in points):
        return 0, 0
    left = int(math.ceil(min(p.x for p in points)))
    bottom = int(math.ceil(min(p.y for p in points)))
    return (left if 0 < left < region.width // 2 else 0,
            bottom if 0 < bottom < region.height // 2 else 0)


def legend_room(context):
    """The bottom-left corner, in the viewport region's pixels, that the legend keeps
    inside: clear of the regions drawn over the viewport and, looking through the camera,
    inside the camera frame."""
    region = context.region
    left, bottom = visible_corner(context.area, region)
    frame_left, frame_bottom = camera_frame_corner(context.scene, region, context.region_data)
    return max(left, frame_left), max(bottom, frame_bottom)


def draw_cascade_legend(snap, plan, width, height, left=0, bottom=0, scale=1.0, rows=None):
    """The cascade-colour legend over a viewport frame drawn with ``plan``, in the bound
    framebuffer: nothing unless Debug View is Cascades. (``left``, ``bottom``): the
    corner the legend keeps inside (``legend_room``); ``scale``: the UI scale.
    Drawn after FXAA, so the swatches and text stay crisp; final renders get none."""
    rows = overlays.cascade_legend(snap, plan) if rows is None else rows
    if not rows:
        return
    import blf
    import gpu
    font = 0
    compat.blf_size(font, max(int(round(11 * scale)), 6))
    text_width = max(blf.dimensions(font, row.label)[0] for row in rows)
    corner = overlays.legend_corner(snap, width, height, left, bottom, scale)
    layout = overlays.legend_layout(rows, text_width, *corner, scale=scale)
    overlays.draw_legend_swatches(layout, width, height)
    from mathutils import Matrix
    with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
        gpu.matrix.load_identity()
        gpu.matrix.load_projection_matrix(Matrix(overlays.pixel_space(width, height).tolist()))
        blf.color(font, 0.92, 0.92, 0.92, 1.0)
        for row, (x, y) in zip(rows, layout.labels):
            blf.position(font, x, y, 0)
            blf.draw(font, row.label)


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


def release_gpu_resources(exiting=True):
    """Free the GPU objects kept between renders (final-render targets, compiled shaders).
    Called when the add-on is disabled and when Python exits: Blender counts anything still
    alive then as leaked and prints "Not freed memory blocks" at exit."""
    _FINAL_RENDER_RESOURCES.clear()
    _FINAL_RENDER_MEMORY.clear()
    for cache in _FINAL_RENDER_MESHES:
        cache.clear()
    shaders.LIBRARY.release()
    if exiting:
        shaders.release_retired()    # nothing draws after this; see the NOTE in shaders.py


# Registered once per process, whatever register/unregister do in between.
atexit.register(release_gpu_resources)


def register():
    bpy.utils.register_class(CSMRenderEngine)
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.add("CSM")


def unregister():
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.discard("CSM")
    bpy.utils.unregister_class(CSMRenderEngine)
    release_gpu_resources(exiting=False)
