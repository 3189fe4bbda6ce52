"""Runs inside a real Blender window (``blender --python gui_student_driver.py -- OUT_DIR
ADDON_ZIP SHADER_COPY``) and walks the path a student takes, for
``test_gui_student_walk.py``.

Owns the in-Blender half of the student walk. As in ``gui_controls_driver.py``, the steps
run from a ``bpy.app.timers`` callback, keys and mouse are real X events sent with
``xdotool``, and the driver checks Blender's state once Blender has handled them:

1. ``installed``: F3 "Preferences", Enter; the Add-ons tab, "Install...", in the file
   browser Ctrl+L, the legacy zip's path, Enter, Enter; the add-on's checkbox (Blender
   filters the list to the add-on it just installed);
2. ``imported``: Properties > Render > Render Engine > CSM; File > Import > CSM Sample
   Scene > Default, chosen with the menus' underlined keys (I, A, D), which replaces the
   startup scene's contents;
3. ``rendered``: Numpad 0, Home, Z pie > Rendered, N, the sidebar's CSM tab;
4. ``preset``: the preset menu in the Cascades panel's header, C ("CS562 assignment");
5. ``blend``: cascade colours (the sidebar scrolled to its end, a click on the Debug
   panel's View dropdown, C), the sidebar scrolled back, a click on the Cascades panel's
   Blend field, 20, Enter; then Lit again (L in the same dropdown);
6. ``first_person``: Shift+F, W held, Esc (the camera goes back);
7. ``shader_folder``: the Shader Folder preference set to a copy of the shaders (by
   script: a file browser in Preferences is the same dialog step 1 drove), F5;
   ``shader_edit``: the copy's lighting_frag.glsl edited (a user's text editor), F5.

After each step it saves ``walk_<n>_<name>.png`` (the main window, or the Preferences
window in step 1) and records the state in ``walk.json`` (``error`` None on success).
"""

import os
import sys

import bpy

# The shared half of the drivers sits beside this file (Blender puts no script folder
# on sys.path).
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gui_common import (  # noqa: E402 (after the path entry)
    FIRST_PERSON, STATE, click_in, count_view_draws, enable_listed_addon, fly_forward,
    fresh_draws, mouse_to_viewport, open_render_engine_menu, pause, record,
    rendered_shading_from_pie, run, screen_height, screen_top, screenshot,
    set_for_screenshots, sidebar, start, until, watch_first_person, window_with, xdotool)

ARGS = sys.argv[sys.argv.index("--") + 1:]
OUT_DIR, ADDON_ZIP, SHADER_COPY = (os.path.abspath(a) for a in ARGS[:3])

BLEND_BAND_M = 20
# Where things are drawn in the fixed 1600x900 window at the default UI scale (measured on
# the screenshots, as in gui_controls_driver.py).
ADDONS_TAB_FROM_TOP_PX = 189
INSTALL_FROM_RIGHT_PX = 157       # Preferences > Add-ons: the "Install..." button
INSTALL_FROM_TOP_PX = 18
FILE_MENU_PX = (46, 13)           # the top bar's "File", from the window's top-left
CSM_TAB_FROM_RIGHT_PX = 12
CSM_TAB_FROM_TOP_PX = 160
PRESET_MENU_FROM_LEFT_PX = 167    # the preset icon in the sidebar's Cascades header
PRESET_MENU_FROM_TOP_PX = 15
BLEND_FROM_LEFT_PX = 139          # the Cascades panel's Blend field
BLEND_FROM_TOP_PX = 321
SCROLL_CLICKS = 30                # wheel clicks that scroll the CSM sidebar end to end
DEBUG_VIEW_FROM_LEFT_PX = 150     # the Debug panel's View dropdown, from the sidebar's
DEBUG_VIEW_FROM_BOTTOM_PX = 324   # bottom-left corner with the sidebar scrolled to its end
# The final colour's tint written into the copy's lighting_frag.glsl in step 7.
TINT = "vec3(1.0, 0.45, 0.45)"

def camera_matrix():
    return [[float(v) for v in row] for row in bpy.context.scene.camera.matrix_world]


def type_path_in_file_browser(path):
    """Ctrl+L, the path, Enter in the open file browser: the file is selected."""
    browser_window, browser_area = window_with('FILE_BROWSER')
    main = next(r for r in browser_area.regions if r.type == 'WINDOW')
    xdotool("mousemove", browser_window.x + main.x + main.width // 2,
            screen_top(browser_window, main) + main.height // 2)
    yield pause(0.3)
    xdotool("key", "ctrl+l")
    yield pause(0.3)
    xdotool("key", "ctrl+a")
    xdotool("type", "--delay", 5, path)
    yield pause(0.2)
    xdotool("key", "Return")
    yield until(f"the path typed in the file browser selected {os.path.basename(path)}",
                lambda: browser_area.spaces.active.params.filename == os.path.basename(path))
    yield pause(0.3)


def sidebar_middle(window, ui):
    return window.x + ui.x + ui.width // 2, screen_top(window, ui) + ui.height // 2


def debug_view(window, ui, key, wanted):
    """The sidebar scrolled to its end, a click on the Debug panel's View dropdown and the
    menu's underlined ``key``."""
    xdotool("mousemove", *sidebar_middle(window, ui))
    yield pause(0.2)
    xdotool("click", "--repeat", SCROLL_CLICKS, "--delay", 15, "5")
    yield pause(0.4)
    xdotool("mousemove", window.x + ui.x + DEBUG_VIEW_FROM_LEFT_PX,
            screen_top(window, ui) + ui.height - DEBUG_VIEW_FROM_BOTTOM_PX)
    yield pause(0.2)
    xdotool("click", "1")
    yield pause(0.5)
    xdotool("key", key)
    yield until(f"{key.upper()} in the Debug View menu chose {wanted}",
                lambda: bpy.context.scene.csm.debug_view == wanted)


# --- the student's walk -------------------------------------------------------------------

def walk():
    window = bpy.context.window_manager.windows[0]
    area = max((a for a in window.screen.areas if a.type == 'VIEW_3D'),
               key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == 'WINDOW')
    STATE.update(window=window, area=area, region=region)
    scene = bpy.context.scene
    startup_objects = sorted(o.name for o in scene.objects)

    # 1. Edit > Preferences (F3 "Preferences"), Add-ons, Install..., the zip, the checkbox.
    yield pause(0.5)
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "F3")
    yield pause(0.5)
    xdotool("type", "--delay", 20, "Preferences")
    yield pause(0.6)
    xdotool("key", "Return")
    yield until("F3 'Preferences' opened the Preferences window",
                lambda: window_with('PREFERENCES') is not None)
    yield pause(0.5)
    prefs_window, prefs_area = window_with('PREFERENCES')
    sections = next(r for r in prefs_area.regions if r.type == 'NAVIGATION_BAR')
    prefs_main = next(r for r in prefs_area.regions if r.type == 'WINDOW')
    yield from click_in(prefs_window, sections, sections.width // 2, ADDONS_TAB_FROM_TOP_PX)
    yield until("a click on the Add-ons tab",
                lambda: bpy.context.preferences.active_section == 'ADDONS')
    yield pause(0.5)
    yield from click_in(prefs_window, prefs_main, prefs_main.width - INSTALL_FROM_RIGHT_PX,
                        INSTALL_FROM_TOP_PX)
    yield until("Install... opened a file browser", lambda: window_with('FILE_BROWSER'))
    yield pause(0.5)
    yield from type_path_in_file_browser(ADDON_ZIP)
    xdotool("key", "Return")
    yield until("Install Add-on put the add-on in the user's add-ons and filtered the list",
                lambda: window_with('FILE_BROWSER') is None
                and "csm" in bpy.context.window_manager.addon_search.lower())
    yield pause(0.8)
    shot = yield from enable_listed_addon(1, "installed")
    import csm_engine
    count_view_draws()
    watch_first_person()
    record(1, "installed", shot, addon_file=csm_engine.__file__,
           addon_search=bpy.context.window_manager.addon_search)

    # 2. Render Engine: CSM; File > Import > CSM Sample Scene > Default (Replace).
    yield from open_render_engine_menu(window)
    xdotool("key", "s")
    yield until("S in the Render Engine menu chose CSM", lambda: scene.render.engine == 'CSM')
    xdotool("mousemove", window.x + FILE_MENU_PX[0], screen_height() - window.y
            - window.height + FILE_MENU_PX[1])
    yield pause(0.2)
    xdotool("click", "1")
    yield pause(0.5)
    xdotool("key", "i")      # Import
    yield pause(0.5)
    xdotool("key", "a")      # CSM Sample Scene
    yield pause(0.5)
    menu = screenshot(2, "import_menu")
    xdotool("key", "d")      # Default
    yield until("File > Import > CSM Sample Scene > Default imported a sun",
                lambda: any(o.type == 'LIGHT' for o in scene.objects))
    from csm_engine.blender import scene_builder
    imported = [c.get("csm_source") for c in scene_builder.imported_collections(scene)]
    objects_after = sorted(o.name for o in scene.objects)
    imported_objects = sorted(o.name for c in scene_builder.imported_collections(scene)
                              for o in c.all_objects)
    space = set_for_screenshots(scene, area)
    yield pause(0.3)
    record(2, "imported", menu, imported=imported, startup_objects=startup_objects,
           objects_after=objects_after, imported_objects=imported_objects,
           engine=scene.render.engine)

    # 3. Through the camera, Rendered shading, the sidebar's CSM tab.
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "KP_0")
    yield until("Numpad 0", lambda: space.region_3d.view_perspective == 'CAMERA')
    xdotool("key", "Home")
    yield pause(0.3)
    xdotool("click", "5")
    yield pause(0.3)
    yield from rendered_shading_from_pie(space)
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "n")
    yield until("N opened the sidebar", lambda: space.show_region_ui)
    yield fresh_draws(2)
    ui = sidebar(area)
    yield from click_in(window, ui, ui.width - CSM_TAB_FROM_RIGHT_PX, CSM_TAB_FROM_TOP_PX)
    yield pause(0.3)
    yield fresh_draws(2)
    record(3, "rendered", screenshot(3, "rendered"), shading=space.shading.type,
           engine=scene.render.engine)

    # 4. The CS562 assignment preset from the Cascades panel's preset menu.
    csm = scene.csm
    before = {"cascade_selection": csm.cascade_selection, "fit_to_visible": csm.fit_to_visible}
    yield from click_in(window, ui, PRESET_MENU_FROM_LEFT_PX, PRESET_MENU_FROM_TOP_PX)
    yield pause(0.6)
    preset_menu = screenshot(4, "preset_menu")
    xdotool("key", "c")
    yield until("C in the preset menu applied CS562 assignment",
                lambda: csm.cascade_selection == 'DEPTH' and not csm.fit_to_visible)
    mouse_to_viewport()
    yield pause(0.3)
    yield fresh_draws(2)
    record(4, "preset", screenshot(4, "preset"), before=before, menu=preset_menu,
           after={"cascade_selection": csm.cascade_selection,
                  "fit_to_visible": csm.fit_to_visible, "blend_band": csm.blend_band,
                  "pcf_sharpen": csm.pcf_sharpen})

    # 5. Cascades (Debug > View > C, the sidebar scrolled to its end), so the band
    # shows; then Blend 2 m -> 20 m: a click on the field, the number typed, Enter.
    yield from debug_view(window, ui, "c", 'CASCADES')
    yield fresh_draws(2)
    cascades = screenshot(5, "cascades")
    xdotool("mousemove", *sidebar_middle(window, ui))
    yield pause(0.2)
    xdotool("click", "--repeat", SCROLL_CLICKS, "--delay", 15, "4")
    yield pause(0.4)
    blend_before = csm.blend_band
    yield from click_in(window, ui, BLEND_FROM_LEFT_PX, BLEND_FROM_TOP_PX)
    yield pause(0.4)
    xdotool("key", "ctrl+a")
    xdotool("type", "--delay", 20, str(BLEND_BAND_M))
    xdotool("key", "Return")
    yield until(f"Blend typed as {BLEND_BAND_M}",
                lambda: abs(csm.blend_band - BLEND_BAND_M) < 1e-4)
    mouse_to_viewport()
    yield pause(0.3)
    yield fresh_draws(2)
    record(5, "blend", screenshot(5, "blend"), blend_before=blend_before,
           blend_after=csm.blend_band, cascades=cascades, debug_view=csm.debug_view)
    # Back to Lit (L in the same menu); the sidebar stays at its end, where the Scene
    # panel shows the shader folder in use.
    yield from debug_view(window, ui, "l", 'NONE')
    mouse_to_viewport()
    yield pause(0.3)
    yield fresh_draws(2)
    lit = screenshot(6, "lit")

    # 6. First person: Shift+F, W held, then Esc puts the camera back.
    start = camera_matrix()
    yield from fly_forward("first person")
    yield fresh_draws(1)
    flying = camera_matrix()
    flying_shot = screenshot(6, "flying")
    xdotool("key", "Escape")
    yield until("Esc ended first person", lambda: not FIRST_PERSON["running"])
    yield fresh_draws(2)
    record(6, "first_person", screenshot(6, "first_person"), camera_before=start,
           camera_flying=flying, camera_after_esc=camera_matrix(), flying=flying_shot,
           lit=lit, invoked=FIRST_PERSON["invoked"])

    # 7. Shader Folder -> a copy of the shaders, F5; the copy edited, F5.
    from csm_engine.blender import preferences
    from csm_engine.render import shaders
    preferences.addon_preferences().shader_folder = SHADER_COPY
    generation = shaders.LIBRARY.generation
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "F5")
    yield until("F5 read the Shader Folder",
                lambda: shaders.LIBRARY.generation > generation)
    # The Scene panel's folder line is two lines now: scroll to the end again to show it.
    xdotool("mousemove", *sidebar_middle(window, ui))
    yield pause(0.2)
    xdotool("click", "--repeat", 5, "--delay", 15, "5")
    mouse_to_viewport()
    yield pause(0.3)
    yield fresh_draws(2)
    record(7, "shader_folder", screenshot(7, "shader_folder"),
           folder_in_use=shaders.LIBRARY.folder_in_use, shader_error=shaders.LIBRARY.last_error)
    path = os.path.join(SHADER_COPY, "lighting_frag.glsl")
    with open(path, encoding="utf-8") as handle:
        source = handle.read()
    final = "  out_color = vec4(color, 1.0);"
    if final not in source:
        raise RuntimeError(f"{path} has no line {final!r} to tint")
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(source.replace(final, f"  out_color = vec4(color * {TINT}, 1.0);"))
    generation = shaders.LIBRARY.generation
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "F5")
    yield until("F5 read the edited shader", lambda: shaders.LIBRARY.generation > generation)
    yield pause(0.3)
    yield fresh_draws(2)
    record(8, "shader_edit", screenshot(8, "shader_edit"),
           folder_in_use=shaders.LIBRARY.folder_in_use, shader_error=shaders.LIBRARY.last_error)


start("gui_student", OUT_DIR, "walk.json", "walk")
run(walk())
