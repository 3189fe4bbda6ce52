"""Runs inside a real Blender window (``blender --python gui_controls_driver.py -- OUT_DIR``)
and walks through the CSM controls the way a user would, for ``test_gui_controls.py``.

Owns the in-Blender half of the GUI controls acceptance test. The steps run one after another
from a ``bpy.app.timers`` callback; keys and mouse come from ``xdotool`` (real X events
through the X server, so Blender's own keymap and event handling dispatch them), and the
driver checks Blender's state on later ticks, once Blender has handled the events:

1. ``addon``: F3 (menu search) "Preferences", Enter; a click on the Add-ons tab, "CSM"
   typed in its search field, a click on the add-on's checkbox (the test installed the
   legacy zip into the user scripts folder, not enabled); record the engine list and the
   CSM sidebar panels;
2. ``panel``: Properties > Render tab > Render Engine dropdown > S (CSM); F3 "CSM
   Scene", Enter (File > Import > CSM Scene), and in the file browser Ctrl+L, the scene
   file's path, Enter, Enter (Replace, the default: the startup objects go); Numpad 0,
   Home and a wheel step out (the camera's frame in view), Z over the viewport and
   a click on the pie's "Rendered", N (the sidebar), and a click on its "CSM" tab;
3. ``cascades``: the sidebar scrolled down with the wheel, a click on the Debug panel's
   "View" dropdown and C (cascade colours); then the same with L (back to Lit);
4. ``f5``: F5 over the viewport (reload shaders); ``f5_error``: a syntax error written
   into the installed add-on's lighting_frag.glsl, F5 (the old shaders keep drawing, the
   error shows); ``f5_fixed``: the file restored, F5 (the fix is picked up);
5. ``light_edited``: a click on the Sun's Outliner row, then R, Z, 4, 0, Enter over the
   viewport: Blender's rotate operator turns it 40 degrees about world Z;
6. ``ctrl_r``: Ctrl+R over the viewport reloads the scene file (sun back to the file);
   ``ctrl_r_undo``: Ctrl+Z (the turned sun is back), Ctrl+Shift+Z (the file's sun again);
7. ``first_person``: Shift+F over the viewport, W held, a left-button drag, Enter (keeps
   the new view); then Shift+F, W held, Esc (cancels: the camera goes back); the camera
   matrix is read after each;
8. ``undo``: a click on the sidebar's "Stabilize" checkbox, then Ctrl+Z, Ctrl+Shift+Z and
   Ctrl+Z over the viewport.

Set by script, not by key or click: the render size (1600x900, the window's aspect),
dithering off and the Standard view transform (so pictures compare pixel for pixel),
overlays, gizmos and the toolbars hidden (clean screenshots), the Preferences window closed
(Xvfb has no window manager to give it a close button), and the broken and fixed shader
file written in step 4 (a user's text editor).

After each step it saves a full-window screenshot ``step_<n>_<name>.png`` and records the
state in ``controls.json`` (with ``error`` None on success). The process ends with
``os._exit`` so no quit dialog can block it.
"""

import math
import os
import sys

import bpy

# The shared half of the drivers sits beside this file (Blender puts no script folder
# on sys.path).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import (  # noqa: E402 (after the path entry)
    FIRST_PERSON, HOLD_W_S, REPORT, STATE, click_in, count_view_draws,
    enable_listed_addon, fly_forward, fresh_draws, menu_search, mouse_to_viewport,
    open_render_engine_menu, pause, record, region_rect, rendered_shading_from_pie, run,
    screen_top, screenshot, set_for_screenshots, sidebar, start, until,
    viewport_centre_on_screen, watch_first_person, window_with, xdotool)

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT_DIR = os.path.abspath(sys.argv[sys.argv.index("--") + 1]) if "--" in sys.argv else os.getcwd()
SCENE_FILE = os.path.join(REPO, "csm_engine", "data", "scenes", "default.json")

SUN_TURN_DEGREES = 40.0
DRAG_PX = (120, 40)          # mouse drag while in first person: right and up, screen pixels
CAMERA_ZOOM_OUT_CLICKS = 1  # wheel steps out after Home in camera view
ADDONS_TAB_FROM_TOP_PX = 189  # Preferences: the "Add-ons" section in its left column
ADDON_SEARCH_FROM_RIGHT_PX = 90  # Preferences > Add-ons: the search field, top right
ADDON_SEARCH_FROM_TOP_PX = 44
ENGINE_MENU_KEY = "s"          # the Render Engine menu's underlined key for "CSM"
AWAY_FROM_REPORT_PX = 200     # mouse move that closes Blender's report popup
SCROLL_CLICKS = 30           # wheel clicks that scroll the CSM sidebar from end to end
DEBUG_VIEW_FROM_LEFT_PX = 150  # the Debug panel's "View" dropdown, from the sidebar's
DEBUG_VIEW_FROM_BOTTOM_PX = 324  # bottom-left corner with the sidebar scrolled to its end
CSM_TAB_FROM_RIGHT_PX = 12   # the "CSM" sidebar tab, from the region's top-right corner
CSM_TAB_FROM_TOP_PX = 160
STABILIZE_FROM_LEFT_PX = 97  # the Cascades panel's "Stabilize" checkbox, from the sidebar's
STABILIZE_FROM_TOP_PX = 253  # top-left corner (same fixed window, CSM tab open)
SUN_ROW_FROM_LEFT_PX = 100   # the Outliner's "Sun" row (fourth: Scene Collection,
SUN_ROW_FROM_TOP_PX = 75     # default, Camera, Sun), from its top-left corner

# No sys.path entry for the checkout: the add-on the user enables is the copy the test
# installed from the legacy zip into the user scripts folder.

def sun():
    from csm_engine.blender import light_controls
    return light_controls.sun_object(bpy.context.scene)


def sun_travel():
    from csm_engine.blender import light_controls
    return [float(v) for v in light_controls.sun_travel(sun())]


def camera_state():
    camera = bpy.context.scene.camera
    matrix = camera.matrix_world
    from csm_engine.core import controls
    yaw, pitch = controls.yaw_pitch(matrix)
    return {"name": camera.name, "location": [float(v) for v in matrix.translation],
            "forward": [float(-matrix[i][2]) for i in range(3)],
            "yaw": float(yaw), "pitch": float(pitch),
            "matrix": [[float(v) for v in row] for row in matrix]}


def file_browser():
    return window_with('FILE_BROWSER')


# --- the user's session -------------------------------------------------------------------

def scenario():
    window = bpy.context.window_manager.windows[0]
    areas = [a for a in window.screen.areas if a.type == 'VIEW_3D']
    area = max(areas, key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == 'WINDOW')
    STATE.update(window=window, area=area, region=region)
    # 1. Enable the add-on (installed from the legacy zip by the test, not enabled yet) in
    # Edit > Preferences, reached with F3 (menu search) "Preferences" + Enter: a click on
    # the Add-ons tab, "CSM" typed in the search field, a click on the add-on's checkbox.
    # Xvfb has no window manager, so there is no title-bar button to close the
    # Preferences window; the driver closes it with wm.window_close.
    yield pause(0.5)
    yield from menu_search("Preferences")
    xdotool("key", "Return")
    yield until("F3 'Preferences' opened the Preferences window",
                lambda: window_with('PREFERENCES') is not None)
    yield pause(0.5)
    prefs_window, prefs_area = window_with('PREFERENCES')
    sections = next(r for r in prefs_area.regions if r.type == 'NAVIGATION_BAR')
    prefs_main = next(r for r in prefs_area.regions if r.type == 'WINDOW')
    screenshot(1, "preferences", prefs_window, prefs_area)
    REPORT["preferences_window"] = {
        "window": [prefs_window.x, prefs_window.y, prefs_window.width, prefs_window.height],
        "sections": region_rect(sections), "main": region_rect(prefs_main)}
    yield from click_in(prefs_window, sections, sections.width // 2, ADDONS_TAB_FROM_TOP_PX)
    yield until("a click on the Add-ons tab",
                lambda: bpy.context.preferences.active_section == 'ADDONS')
    yield pause(0.5)
    screenshot(1, "addons_tab", prefs_window, prefs_area)
    yield from click_in(prefs_window, prefs_main, prefs_main.width - ADDON_SEARCH_FROM_RIGHT_PX,
                        ADDON_SEARCH_FROM_TOP_PX)
    yield pause(0.3)
    xdotool("type", "--delay", 20, "CSM")
    xdotool("key", "Return")
    yield until("'CSM' typed in the add-on search",
                lambda: bpy.context.window_manager.addon_search.lower() == "csm")
    yield pause(0.5)
    addon_enabled = yield from enable_listed_addon(1, "addon_enabled")
    import csm_engine
    from csm_engine.blender import ui
    count_view_draws()
    watch_first_person()
    engines = sorted(cls.bl_idname for cls in bpy.types.RenderEngine.__subclasses__())
    sidebar_panels = sorted(
        cls.bl_idname for cls in ui.classes
        if cls.bl_space_type == 'VIEW_3D' and cls.bl_region_type == 'UI'
        and getattr(cls, "bl_category", "") == "CSM"
        and hasattr(bpy.types, cls.bl_idname))
    yield pause(0.2)
    record(1, "addon", screenshot(1, "addon"), engines=engines, sidebar_panels=sidebar_panels,
           addon_file=csm_engine.__file__, addon_enabled=addon_enabled,
           window_size=[window.width, window.height])

    # 2. The user's set-up, all through the window: Properties > Render tab > Render Engine
    # dropdown > CSM; F3 (menu search) "CSM Scene" + Enter runs File > Import > CSM Scene
    # (.json), and in its file browser Ctrl+L (edit the directory), the scene file's path,
    # Enter (a file path typed there selects that file), Enter (import, replacing the
    # current scene's contents by default: the startup cube, camera and lamp go).
    scene = bpy.context.scene
    startup_objects = sorted(o.name for o in scene.objects)
    yield from open_render_engine_menu(window)
    engine_menu = screenshot(2, "engine_menu")
    xdotool("key", ENGINE_MENU_KEY)
    yield until(f"{ENGINE_MENU_KEY} in the Render Engine menu chose CSM",
                lambda: scene.render.engine == 'CSM')
    yield from menu_search("CSM Scene")
    search = screenshot(2, "menu_search")
    xdotool("key", "Return")
    yield until("F3 'CSM Scene' opened a file browser", lambda: file_browser() is not None)
    yield pause(0.5)
    browser_window, browser_area = file_browser()
    browser_main = next(r for r in browser_area.regions if r.type == 'WINDOW')
    xdotool("mousemove", browser_window.x + browser_main.x + browser_main.width // 2,
            screen_top(browser_window, browser_main) + browser_main.height // 2)
    yield pause(0.3)
    xdotool("key", "ctrl+l")
    yield pause(0.3)
    xdotool("key", "ctrl+a")
    xdotool("type", "--delay", 5, SCENE_FILE)
    yield pause(0.2)
    xdotool("key", "Return")
    yield until("the path typed in the file browser selected default.json",
                lambda: browser_area.spaces.active.params.filename == os.path.basename(SCENE_FILE))
    yield pause(0.3)
    file_chosen = screenshot(2, "file_browser", browser_window, browser_area)
    xdotool("key", "Return")
    yield until("Enter in the file browser imported the scene", lambda: (
        file_browser() is None and any(o.type == 'LIGHT' for o in scene.objects)))
    from csm_engine.blender import scene_builder
    imported = [{"name": c.name, "source": c.get("csm_source")}
                for c in scene_builder.imported_collections(scene)]
    objects_after_import = sorted(o.name for o in scene.objects)
    imported_objects = sorted(o.name for c in scene_builder.imported_collections(scene)
                              for o in c.all_objects)
    space = set_for_screenshots(scene, area)
    # Through the imported camera: Numpad 0, Home (fit the camera frame to the view), and
    # the wheel out a little so the whole frame shows beside the sidebar.
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "KP_0")
    yield until("Numpad 0 looked through the camera",
                lambda: space.region_3d.view_perspective == 'CAMERA')
    xdotool("key", "Home")
    yield pause(0.3)
    xdotool("click", "--repeat", CAMERA_ZOOM_OUT_CLICKS, "--delay", 50, "5")
    yield pause(0.3)
    shading_before = space.shading.type
    yield from rendered_shading_from_pie(space)
    yield fresh_draws(2)
    # The same view before the sidebar opens, so the test can see what the panel changed.
    before_sidebar = screenshot(2, "before_sidebar")
    sidebar_before_n = space.show_region_ui
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "n")
    yield until("N over the viewport opened the sidebar", lambda: space.show_region_ui)
    yield fresh_draws(2)
    # The sidebar opens on its first tab ("Item"); a user clicks the "CSM" tab, the fourth
    # of the vertical tabs on its right edge. Blender 3.4 has no Python access to the active
    # tab, so the click goes where the tab is drawn (measured on this fixed 1600x900 window
    # at the default UI scale); the test checks the screenshot shows the CSM panels.
    ui_region = sidebar(area)
    yield from click_in(window, ui_region, ui_region.width - CSM_TAB_FROM_RIGHT_PX,
                        CSM_TAB_FROM_TOP_PX)
    yield pause(0.3)
    yield fresh_draws(2)
    record(2, "panel", screenshot(2, "panel"), imported=imported, engine_menu=engine_menu,
           menu_search=search, file_browser=file_chosen, scene_file=SCENE_FILE,
           engine=scene.render.engine, shading=space.shading.type,
           view_perspective=space.region_3d.view_perspective,
           before_sidebar=before_sidebar, shading_before=shading_before,
           sidebar_before_n=sidebar_before_n, startup_objects=startup_objects,
           objects_after_import=objects_after_import, imported_objects=imported_objects,
           sun_travel=sun_travel(),
           file_sun_direction=[float(v) for v in _file_direction()])

    # 3. Cascades, chosen in the sidebar's Debug panel: scroll the sidebar to its end
    # (the Debug panel is below the fold at this window size), click the "View" dropdown
    # and press C, the menu's underlined key for "Cascades". Back to "Lit" (L) the
    # same way, then scroll back to the top for step 8's click on Stabilize.
    ui_region = sidebar(area)
    top_on_screen = screen_top(window, ui_region)
    bottom_on_screen = top_on_screen + ui_region.height
    middle = (window.x + ui_region.x + ui_region.width // 2, top_on_screen + ui_region.height // 2)
    debug_view_field = (window.x + ui_region.x + DEBUG_VIEW_FROM_LEFT_PX,
                        bottom_on_screen - DEBUG_VIEW_FROM_BOTTOM_PX)
    xdotool("mousemove", *middle)
    yield pause(0.2)
    xdotool("click", "--repeat", SCROLL_CLICKS, "--delay", 15, "5")
    yield pause(0.4)
    scrolled = screenshot(3, "scrolled")
    views = []
    for key, wanted in (("c", 'CASCADES'), ("l", 'NONE')):
        xdotool("mousemove", *debug_view_field)
        yield pause(0.2)
        xdotool("click", "1")
        yield pause(0.5)
        if wanted == 'CASCADES':
            menu = screenshot(3, "debug_menu")
        xdotool("key", key)
        yield until(f"the Debug View menu's {key.upper()} chose {wanted}",
                    lambda wanted=wanted: scene.csm.debug_view == wanted)
        yield fresh_draws(2)
        views.append(scene.csm.debug_view)
        if wanted == 'CASCADES':
            record(3, "cascades", screenshot(3, "cascades"), debug_view=scene.csm.debug_view,
                   scrolled=scrolled, menu=menu)
    xdotool("mousemove", *middle)
    yield pause(0.2)
    xdotool("click", "--repeat", SCROLL_CLICKS, "--delay", 15, "4")
    yield pause(0.4)
    REPORT["steps"][-1]["debug_view_after_l"] = views[-1]

    # 4. F5 over the viewport reloads the shaders.
    from csm_engine.render import shaders
    generation = shaders.LIBRARY.generation
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "F5")
    yield until("F5 reloaded the shaders", lambda: shaders.LIBRARY.generation > generation)
    yield fresh_draws(2)
    record(4, "f5", screenshot(4, "f5"), generation_before=generation,
           generation_after=shaders.LIBRARY.generation, shader_error=shaders.LIBRARY.last_error)

    # 4b. A syntax error in the add-on's lighting_frag.glsl (the installed copy), F5: the
    # viewport keeps drawing with the previous shaders and the error shows; the file fixed
    # again, F5 picks the fix up.
    import csm_engine
    shader_file = os.path.join(os.path.dirname(csm_engine.__file__), "shaders",
                               "lighting_frag.glsl")
    with open(shader_file, encoding="utf-8") as handle:
        good_source = handle.read()
    lines = good_source.splitlines()
    broken_line = lines.index("{") + 2
    lines.insert(broken_line - 1, "  float broken = ;")
    generation = shaders.LIBRARY.generation
    try:
        with open(shader_file, "w", encoding="utf-8") as handle:
            handle.write("\n".join(lines) + "\n")
        mouse_to_viewport()
        yield pause(0.2)
        xdotool("key", "F5")
        yield until("F5 reported the broken shader", lambda: shaders.LIBRARY.last_error)
        draws_before = STATE["draws"]
        yield fresh_draws(2)
        yield pause(0.3)
        # Blender shows the operator's error report in a popup at the mouse; moving the
        # mouse away closes it (and a key pressed over it would go to the popup).
        report = screenshot(4, "f5_error_report")
        report_at = viewport_centre_on_screen()
        x, y = report_at
        xdotool("mousemove", x, y + AWAY_FROM_REPORT_PX)
        yield pause(0.5)
        yield fresh_draws(2)
        record(4, "f5_error", screenshot(4, "f5_error"), shader_error=shaders.LIBRARY.last_error,
               broken_line=broken_line, generation_before=generation,
               generation_after=shaders.LIBRARY.generation,
               draws_after_error=STATE["draws"] - draws_before,
               draw_error=STATE["draw_error"], report_screenshot=report,
               report_at=list(report_at))
    finally:
        with open(shader_file, "w", encoding="utf-8") as handle:
            handle.write(good_source)
    yield pause(0.2)
    xdotool("key", "F5")
    yield until("F5 picked up the fixed shader", lambda: (
        shaders.LIBRARY.generation > generation and shaders.LIBRARY.last_error is None))
    yield fresh_draws(2)
    yield pause(0.3)
    record(4, "f5_fixed", screenshot(4, "f5_fixed"), shader_error=shaders.LIBRARY.last_error,
           generation_before=generation, generation_after=shaders.LIBRARY.generation)

    # 5. Turn the sun in the viewport: click its row in the Outliner (selects only the Sun),
    # then R, Z, 40, Enter with the mouse over the 3D View (Blender's own rotate operator;
    # a turn about world Z changes the azimuth only).
    from csm_engine.core import controls
    sun_before = sun_travel()
    outliner = next(r for a in window.screen.areas if a.type == 'OUTLINER'
                    for r in a.regions if r.type == 'WINDOW')
    yield from click_in(window, outliner, SUN_ROW_FROM_LEFT_PX, SUN_ROW_FROM_TOP_PX)
    yield until("the Outliner click selected only the Sun", lambda: (
        [o.name for o in bpy.context.scene.objects if o.select_get()] == [sun().name]
        and bpy.context.view_layer.objects.active == sun()))
    yield fresh_draws(1)
    mouse_to_viewport()
    yield pause(0.2)
    for key in ("r", "z", "4", "0", "Return"):
        xdotool("key", key)
        yield pause(0.1)
    yield until("the sun turned", lambda: _angle(sun_travel(), sun_before) > 1.0)
    yield pause(0.3)
    yield fresh_draws(2)
    edited = sun_travel()
    record(5, "light_edited", screenshot(5, "light_edited"), sun_before=list(sun_before),
           sun_after=edited, turned_degrees=_angle(edited, sun_before),
           azimuth_elevation_before=list(controls.azimuth_elevation_from_travel(sun_before)),
           azimuth_elevation_after=list(controls.azimuth_elevation_from_travel(edited)),
           engine=scene.render.engine, shading=space.shading.type,
           file_sun_direction=[float(v) for v in _file_direction()])

    # 6. Ctrl+R over the viewport reloads the scene file: the sun goes back to its direction.
    mouse_to_viewport()
    yield pause(0.2)
    old_sun_name = sun().name_full
    xdotool("key", "ctrl+r")
    yield until("Ctrl+R put the sun back",
                lambda: sun() is not None and _angle(sun_travel(), _file_direction()) < 1e-3)
    yield pause(0.3)
    yield fresh_draws(2)
    scene = bpy.context.scene
    record(6, "ctrl_r", screenshot(6, "ctrl_r"), sun_after=sun_travel(),
           file_sun_direction=[float(v) for v in _file_direction()],
           sun_name_before=old_sun_name, sun_name_after=sun().name_full,
           engine=scene.render.engine, shading=space.shading.type,
           view_perspective=space.region_3d.view_perspective, camera=camera_state())

    # 6b. Ctrl+Z over the viewport undoes the reload (the turned sun is back), Ctrl+Shift+Z
    # redoes it (the file's sun again).
    undo_states = []
    for keys, wanted, number, name in (("ctrl+z", edited, 6, "ctrl_z"),
                                       ("ctrl+shift+z", _file_direction(), 6, "ctrl_shift_z")):
        mouse_to_viewport()
        yield pause(0.2)
        xdotool("key", keys)
        yield until(f"{keys} turned the sun to {wanted}",
                    lambda wanted=wanted: sun() is not None
                    and _angle(sun_travel(), wanted) < 1e-3)
        yield pause(0.3)
        yield fresh_draws(2)
        undo_states.append({"keys": keys, "sun": sun_travel(),
                            "engine": bpy.context.scene.render.engine,
                            "imported": sorted(c.name for c in bpy.data.collections
                                               if "csm_source" in c),
                            "screenshot": screenshot(number, name)})
    record(6, "ctrl_r_undo", undo_states[0]["screenshot"], undo_states=undo_states,
           sun_edited=edited, file_sun_direction=[float(v) for v in _file_direction()])

    # 7. First person: Shift+F over the viewport, hold W, drag the mouse, Enter.
    start = camera_state()
    yield from fly_forward("the first-person camera")
    after_w = camera_state()
    x, y = viewport_centre_on_screen()
    xdotool("mousedown", "1")
    yield pause(0.1)
    steps = 6
    for i in range(1, steps + 1):
        xdotool("mousemove", x + DRAG_PX[0] * i // steps, y - DRAG_PX[1] * i // steps)
        yield pause(0.05)
    yield pause(0.2)
    xdotool("mouseup", "1")
    yield pause(0.3)
    yield fresh_draws(1)
    after_drag = camera_state()
    xdotool("key", "Return")
    yield until("Enter confirmed the first-person camera", lambda: not FIRST_PERSON["running"])
    yield fresh_draws(2)
    after_enter = camera_state()
    shot = screenshot(7, "first_person")
    # Again, then Esc: the flight is cancelled and the camera goes back to where Enter left it.
    yield from fly_forward("the first-person camera again")
    before_esc = camera_state()
    xdotool("key", "Escape")
    yield until("Esc cancelled the first-person camera", lambda: not FIRST_PERSON["running"])
    yield fresh_draws(2)
    record(7, "first_person", shot, camera_before=start,
           camera_after_w=after_w, camera_after_drag=after_drag, camera_after_enter=after_enter,
           camera_before_esc=before_esc, camera_after_esc=camera_state(),
           invoked=FIRST_PERSON["invoked"], running=FIRST_PERSON["running"],
           hold_w_s=HOLD_W_S, drag_px=list(DRAG_PX),
           view_perspective=space.region_3d.view_perspective)

    # 8. Undo: click the sidebar's "Stabilize" checkbox (off), Ctrl+Z over the viewport
    # (back on, the camera stays where first person left it), Ctrl+Shift+Z (off again),
    # Ctrl+Z (on again) for the screenshot.
    before_click = bpy.context.scene.csm.stabilize
    ui_region = sidebar(area)
    yield from click_in(window, ui_region, STABILIZE_FROM_LEFT_PX, STABILIZE_FROM_TOP_PX)
    yield until("the Stabilize click toggled it",
                lambda: bpy.context.scene.csm.stabilize != before_click)
    after_click = bpy.context.scene.csm.stabilize
    yield fresh_draws(1)
    camera_before_undo = camera_state()
    undo_states = []
    for keys, wanted in (("ctrl+z", before_click), ("ctrl+shift+z", after_click),
                         ("ctrl+z", before_click)):
        mouse_to_viewport()
        yield pause(0.2)
        xdotool("key", keys)
        yield until(f"{keys} set Stabilize to {wanted}",
                    lambda wanted=wanted: bpy.context.scene.csm.stabilize == wanted)
        yield pause(0.3)
        yield fresh_draws(2)
        undo_states.append({"keys": keys, "stabilize": bpy.context.scene.csm.stabilize,
                            "engine": bpy.context.scene.render.engine,
                            "camera": camera_state()})
    record(8, "undo", screenshot(8, "undo"), stabilize_before_click=before_click,
           stabilize_after_click=after_click, camera_before_undo=camera_before_undo,
           undo_states=undo_states, sun_travel=sun_travel(),
           file_sun_direction=[float(v) for v in _file_direction()])



def _angle(a, b):
    dot = sum(x * y for x, y in zip(a, b))
    na = math.sqrt(sum(x * x for x in a))
    nb = math.sqrt(sum(x * x for x in b))
    return math.degrees(math.acos(max(-1.0, min(1.0, dot / (na * nb)))))


def _file_direction():
    from csm_engine.blender import light_controls
    direction = light_controls.file_sun_direction(sun())
    if direction is None:
        raise RuntimeError("the imported Sun has no stored scene-file direction")
    return direction


def error_state():
    return {"camera": str(bpy.context.scene.camera), "draws": STATE["draws"],
            "engine": bpy.context.scene.render.engine,
            "scenes": [sc.name for sc in bpy.data.scenes],
            "window_scene": STATE["window"].scene.name,
            "shading": STATE["area"].spaces.active.shading.type,
            "registered": hasattr(bpy.types, "CSM_PT_view_3d_light")}


start("gui_controls", OUT_DIR, "controls.json", "step")
run(scenario(), error_state)
