"""Runs inside a real Blender window (``blender -p 0 0 W H -P gui_driver.py -- OUT_DIR``) and
records what the 3D viewport shows in CSM rendered mode, for ``test_gui_viewport.py``.

Owns the in-Blender half of the GUI test: import the default scene into an empty startup
scene, switch the biggest 3D viewport to Rendered shading with the CSM engine, look through
the scene camera with the camera frame fitted to the view, wait until the engine has drawn,
save a full-window screenshot, then render the same camera with F12 semantics
(``render.render(write_still=True)``) at the size the camera frame has on screen.

It writes into OUT_DIR:
- ``viewport.png``: the whole Blender window, top row first;
- ``render.png``: the F12 render;
- ``render_no_shadows.png``: the same render with the sun's shadow turned off;
- ``terminator_0.1.png``, ``terminator_0.png``: the window after a low-poly smooth sphere
  was added in front of the camera, with its Shadow Terminator Geometry Offset at 0.1 and
  then edited to 0 (as the UI's edit reaches the engine: the value set and the object
  tagged in the depsgraph, no redraw asked for by the driver);
- ``viewport.json``: window size, the camera frame rectangle in window pixels (origin at the
  window's bottom-left, as Blender counts), timings, the number of viewport draws and mesh
  uploads, and ``error`` (None on success).

Everything runs from ``bpy.app.timers`` callbacks, because a ``-P`` script runs before the
window has drawn once. The process exits with ``os._exit`` so no quit dialog can block it.
"""

import os
import sys
import time
import traceback

import bpy

sys.dont_write_bytecode = True   # no __pycache__ in the checkout
# The shared half of the drivers sits beside this file (Blender puts no script folder
# on sys.path).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import REPORT, STATE, count_view_draws, finish, log, start  # noqa: E402

# Never hard-code the clone's location: tests/hosts/gui_driver.py -> repository root.
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT_DIR = os.path.abspath(sys.argv[sys.argv.index("--") + 1]) if "--" in sys.argv else os.getcwd()
SCENE_FILE = os.path.join(REPO, "csm_engine", "data", "scenes", "default.json")

TICK_S = 0.05               # timer period while waiting for Blender to draw
DRAWS_AFTER_SETUP = 1       # complete viewport draws to wait for after the last view change
# Blender's camera zoom steps; a little smaller than "fit" keeps the camera frame clear of
# the region's edge widgets (the arrows that reopen the toolbar and sidebar).
CAMERA_ZOOM_OUT = 3.0
FRAME_MARGIN_PX = 12        # the frame must stay this far inside the viewport region
WAIT_LIMIT_S = 60.0         # give up (and say why) if the engine never draws
VIEWPORT_ASPECT = (16, 9)   # camera frame aspect while the viewport is captured
SPHERE_DISTANCE = 40.0      # scene units in front of the camera (default.json's scale)
SPHERE_RADIUS = 6.0

if REPO not in sys.path:
    sys.path.insert(0, REPO)

start("gui_driver", OUT_DIR, "viewport.json", "viewport")
STATE.update(step="setup", draws_at_mark=0)


def empty_startup_scene():
    """Remove the startup file's cube, light, camera and world, as the command line's
    ``read_factory_settings(use_empty=True)`` does, so the viewport shows what the CLI renders
    (the import then gives the scene its own sky)."""
    for collection in (bpy.data.objects, bpy.data.meshes, bpy.data.materials, bpy.data.lights,
                       bpy.data.cameras, bpy.data.worlds):
        for datablock in list(collection):
            collection.remove(datablock)


def biggest_view3d(window):
    areas = [a for a in window.screen.areas if a.type == 'VIEW_3D']
    if not areas:
        raise RuntimeError("the startup screen has no 3D viewport")
    area = max(areas, key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == 'WINDOW')
    return area, region


def setup():
    import csm_engine
    from csm_engine.blender import scene_builder
    csm_engine.register()
    count_view_draws()

    empty_startup_scene()
    scene = bpy.context.scene
    scene_builder.import_scene_file(SCENE_FILE, scene)
    render = scene.render
    render.engine = 'CSM'
    # Only the aspect matters while the viewport is captured; F12 later renders at the size
    # the camera frame has on screen.
    render.resolution_x, render.resolution_y = 1600, 1600 * VIEWPORT_ASPECT[1] // VIEWPORT_ASPECT[0]
    render.resolution_percentage = 100
    render.image_settings.file_format = 'PNG'
    render.image_settings.color_mode = 'RGB'
    render.image_settings.color_depth = '8'
    # Dither adds per-pixel noise to both the display and the saved render: off, so the two
    # images differ only where the pipeline does.
    render.dither_intensity = 0.0
    # One render sample: F12 then goes through the same FXAA pass as the viewport, so the
    # two images differ only where rasterization does (8 jittered samples would soften
    # every edge a little more than FXAA does).
    scene.csm.render_samples = 1
    scene.view_settings.view_transform = 'Standard'
    scene.view_settings.look = 'None'
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0

    window = bpy.context.window_manager.windows[0]
    area, region = biggest_view3d(window)
    space = area.spaces.active
    space.shading.type = 'RENDERED'
    space.overlay.show_overlays = False
    space.show_gizmo = False
    space.show_region_toolbar = False
    space.show_region_ui = False
    # The tool settings bar is drawn over the top of the region, inside the camera frame.
    space.show_region_tool_header = False
    region_3d = space.region_3d
    region_3d.view_perspective = 'CAMERA'
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.view3d.view_center_camera()
    region_3d.view_camera_zoom -= CAMERA_ZOOM_OUT
    # Show the engine's own settings next to the viewport in the screenshot.
    for other in window.screen.areas:
        if other.type == 'PROPERTIES':
            other.spaces.active.context = 'RENDER'
    STATE.update(window=window, area=area, region=region)
    REPORT["scene_file"] = SCENE_FILE
    REPORT["objects"] = sorted(o.name for o in scene.objects)


def camera_frame_in_window(scene, region, region_3d):
    """The camera frame's corners projected into window pixels (bottom-left origin)."""
    from bpy_extras.view3d_utils import location_3d_to_region_2d
    camera = scene.camera
    corners = [camera.matrix_world @ corner for corner in camera.data.view_frame(scene=scene)]
    points = [location_3d_to_region_2d(region, region_3d, corner) for corner in corners]
    if any(p is None for p in points):
        raise RuntimeError("the camera frame is behind the viewport camera")
    xs = [region.x + p.x for p in points]
    ys = [region.y + p.y for p in points]
    return {"x_min": min(xs), "x_max": max(xs), "y_min": min(ys), "y_max": max(ys)}


def capture():
    window, area, region = STATE["window"], STATE["area"], STATE["region"]
    scene = bpy.context.scene
    shot = os.path.join(OUT_DIR, "viewport.png")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.screenshot(filepath=shot, check_existing=False)
    if not os.path.isfile(shot):
        raise RuntimeError(f"screen.screenshot did not write {shot}")
    frame = camera_frame_in_window(scene, region, area.spaces.active.region_3d)
    inside = (frame["x_min"] - region.x, region.x + region.width - frame["x_max"],
              frame["y_min"] - region.y, region.y + region.height - frame["y_max"])
    if min(inside) < FRAME_MARGIN_PX:
        raise RuntimeError(f"camera frame {frame} is not {FRAME_MARGIN_PX} px inside the "
                           f"viewport region {region.x, region.y, region.width, region.height}")
    REPORT.update(window_size=[window.width, window.height],
                  viewport_region={"x": region.x, "y": region.y,
                                   "width": region.width, "height": region.height},
                  camera_frame=frame, viewport_draws=STATE["draws"])


def render_still():
    """F12 at the on-screen size of the camera frame, so the comparison resamples little."""
    scene = bpy.context.scene
    frame = REPORT["camera_frame"]
    width = max(int(round(frame["x_max"] - frame["x_min"])), 16)
    render = scene.render
    render.resolution_x = width
    render.resolution_y = max(int(round(width * VIEWPORT_ASPECT[1] / VIEWPORT_ASPECT[0])), 9)
    render.filepath = os.path.join(OUT_DIR, "render.png")
    from csm_engine.blender import engine
    started = time.monotonic()
    result = engine.render_final(scene, write_still=True)
    REPORT["timings_s"]["render"] = round(time.monotonic() - started, 3)
    if result.error:
        raise RuntimeError("CSM render failed: " + result.error)
    if not os.path.isfile(render.filepath):
        raise RuntimeError(f"render.render(write_still=True) did not write {render.filepath}")
    REPORT["render_size"] = [render.resolution_x, render.resolution_y]

    # The same frame without sun shadows: the test's control that a viewport missing the
    # shadows would not pass for the CSM render.
    for obj in scene.objects:
        if obj.type == 'LIGHT':
            obj.data.use_shadow = False
    render.filepath = os.path.join(OUT_DIR, "render_no_shadows.png")
    result = engine.render_final(scene, write_still=True)
    if result.error or not os.path.isfile(render.filepath):
        raise RuntimeError(f"the render without shadows failed: {result.error}")


def set_terminator_offset(obj, value):
    """What an edit of Geometry Offset in Properties > Object > Shadow Terminator does
    (CSM's panel; Blender 5.0 keeps the value on the ``Object``, 3.x/4.x on the Cycles
    add-on's ``object.cycles``). NOTE: a property an add-on defines (``object.cycles``)
    updates nothing when Python sets it (``RNA_property_update_check`` is false for it),
    while the UI's edit tags its ID in the depsgraph and sends NC_WINDOW
    (``rna_property_update``, the PROP_IDPROPERTY branch). ``update_tag`` stands in for the
    tag, and is what Blender asks scripts to call (T74000); it sends no notifier, so the
    engine alone must bring the redraw: the harder case of the two."""
    from csm_engine.blender import compat
    compat.terminator_offset_owner(obj).shadow_terminator_geometry_offset = value
    obj.update_tag()


def add_terminator_sphere():
    """Sun shadows back on, and a 12-segment smooth-shaded sphere in front of the camera:
    its facets turned from the sun but smooth-shaded toward it are the terminator band."""
    import bmesh
    from mathutils import Vector
    scene = bpy.context.scene
    for obj in scene.objects:
        if obj.type == 'LIGHT':
            obj.data.use_shadow = True
    camera = scene.camera.matrix_world
    location = camera.translation + camera.to_3x3() @ Vector((0.0, 0.0, -SPHERE_DISTANCE))
    mesh = bpy.data.meshes.new("TerminatorSphere")
    shape = bmesh.new()
    bmesh.ops.create_uvsphere(shape, u_segments=12, v_segments=6, radius=SPHERE_RADIUS)
    shape.to_mesh(mesh)
    shape.free()
    for polygon in mesh.polygons:
        polygon.use_smooth = True
    sphere = bpy.data.objects.new("TerminatorSphere", mesh)
    sphere.location = location
    scene.collection.objects.link(sphere)
    set_terminator_offset(sphere, 0.1)
    return sphere


def screenshot(name):
    window, area, region = STATE["window"], STATE["area"], STATE["region"]
    shot = os.path.join(OUT_DIR, name)
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.screenshot(filepath=shot, check_existing=False)
    if not os.path.isfile(shot):
        raise RuntimeError(f"screen.screenshot did not write {shot}")


def tick():
    try:
        step = STATE["step"]
        elapsed = time.monotonic() - STATE["started"]
        if STATE["draw_error"]:
            raise RuntimeError("the CSM viewport draw failed:\n" + STATE["draw_error"])
        if elapsed > WAIT_LIMIT_S:
            raise RuntimeError(f"gave up in step '{step}' after {elapsed:.0f} s: "
                               f"{STATE['draws']} viewport draws seen")
        if step == "setup":
            setup()
            REPORT["timings_s"]["setup"] = round(time.monotonic() - STATE["started"], 3)
            log("scene imported, viewport in CSM rendered mode")
            STATE["step"] = "first_draw"
        elif step == "first_draw":
            uploads = STATE.get("mesh_uploads", 0)
            if STATE["draws"] > 0 and uploads > 0:
                REPORT["mesh_uploads"] = uploads
                REPORT["timings_s"]["first_draw"] = round(elapsed, 3)
                log(f"engine drew ({uploads} mesh uploads)")
                # Whatever the first draw saw, ask for fresh ones with the final view.
                STATE["draws_at_mark"] = STATE["draws"]
                STATE["area"].tag_redraw()
                STATE["step"] = "settle"
        elif step == "settle":
            if STATE["draws"] - STATE["draws_at_mark"] >= DRAWS_AFTER_SETUP:
                # This timer runs after the window was swapped, so the screenshot holds the
                # last complete draw.
                capture()
                log(f"screenshot taken after {STATE['draws']} viewport draws")
                render_still()
                log("F12 render written")
                STATE["sphere"] = add_terminator_sphere()
                STATE["draws_at_mark"] = STATE["draws"]
                STATE["area"].tag_redraw()
                STATE["step"] = "sphere_draw"
            else:
                STATE["area"].tag_redraw()
        elif step == "sphere_draw":
            if STATE["draws"] - STATE["draws_at_mark"] >= 2:
                screenshot("terminator_0.1.png")
                log("screenshot with the sphere's offset at 0.1")
                # The edit alone must bring a new draw: no tag_redraw from here on.
                set_terminator_offset(STATE["sphere"], 0.0)
                STATE["draws_at_mark"] = STATE["draws"]
                STATE["edited_at"] = time.monotonic()
                STATE["step"] = "edit_draw"
            else:
                STATE["area"].tag_redraw()
        elif step == "edit_draw":
            if STATE["draws"] - STATE["draws_at_mark"] >= 1:
                # The first draw the edit brought, as it was swapped to the window.
                screenshot("terminator_0.png")
                REPORT["terminator_edit"] = {
                    "draws_after_edit": STATE["draws"] - STATE["draws_at_mark"],
                    "seconds_to_redraw": round(time.monotonic() - STATE["edited_at"], 3)}
                log("screenshot with the sphere's offset at 0")
                finish(0)
            elif time.monotonic() - STATE["edited_at"] > 10.0:
                raise RuntimeError("the viewport did not draw again within 10 s of an "
                                   "edit of the sphere's Shadow Terminator Geometry Offset")
        return TICK_S
    except Exception:
        REPORT["error"] = traceback.format_exc()
        print(REPORT["error"], file=sys.stderr, flush=True)
        finish(1)


os.makedirs(OUT_DIR, exist_ok=True)
bpy.app.timers.register(tick, first_interval=TICK_S)
