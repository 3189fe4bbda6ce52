"""The in-Blender half shared by the GUI drivers that play a user's session
(``gui_controls_driver.py``, ``gui_student_driver.py``) and the viewport driver
(``gui_driver.py``, which uses its session, log and draw counting only).

Owns what every such session needs: real X key and mouse events through ``xdotool``,
Blender's window and region coordinates turned into screen pixels, screenshots and the JSON
record of each step, counting the viewport's finished draws, and the timer that runs a
scenario. A scenario is a generator that yields ``until(name, condition)`` steps; the timer
resumes it once the condition holds, and fails the run, naming the condition, when it does
not hold within ``WAIT_LIMIT_S``.

A driver calls ``start(...)`` with its name, output folder and file names, then
``run(scenario)``. The session ends with ``os._exit`` so no quit dialog can block it.
"""

import json
import os
import subprocess
import sys
import time
import traceback

import bpy

TICK_S = 0.05
WAIT_LIMIT_S = 30.0          # one condition that never comes true fails the run with its name
TOTAL_LIMIT_S = 150.0

sys.dont_write_bytecode = True   # no __pycache__ in the checkout

STATE = {"started": time.monotonic(), "draws": 0, "draw_error": None, "mesh_uploads": 0,
         "window": None, "area": None, "region": None, "condition": None,
         "condition_name": "", "condition_since": 0.0}
REPORT = {"error": None, "blender": bpy.app.version_string, "steps": [], "timings_s": {}}
FIRST_PERSON = {"running": False, "invoked": 0}
SESSION = {"name": "gui", "out_dir": os.getcwd(), "report_file": "report.json",
           "shot_prefix": "step"}


def start(name, out_dir, report_file, shot_prefix):
    """Name the session (log lines), and where its screenshots and report go."""
    SESSION.update(name=name, out_dir=out_dir, report_file=report_file,
                   shot_prefix=shot_prefix)
    os.makedirs(out_dir, exist_ok=True)


def log(message):
    print(f"{SESSION['name']}: {time.monotonic() - STATE['started']:6.2f} s: {message}",
          flush=True)


def finish(exit_code):
    REPORT["timings_s"]["total"] = round(time.monotonic() - STATE["started"], 3)
    with open(os.path.join(SESSION["out_dir"], SESSION["report_file"]), "w") as handle:
        json.dump(REPORT, handle, indent=2)
    log(f"done, exit code {exit_code}")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(exit_code)


# --- Blender's windows --------------------------------------------------------------------

def count_view_draws():
    """Wrap the engine's view_draw to know when the viewport has really drawn a frame, and
    how many meshes it has uploaded so far. Blender looks the method up on the class at
    every call, so wrapping it after registration reaches the engine instance the viewport
    creates."""
    from csm_engine.blender import engine
    original = engine.CSMRenderEngine.view_draw

    def view_draw(self, context, depsgraph):
        try:
            original(self, context, depsgraph)
        except Exception:
            # Blender would only print it; the timer stops at its next tick and reports it.
            STATE["draw_error"] = traceback.format_exc()
            raise
        STATE["draws"] += 1
        STATE["mesh_uploads"] = self.snapshots.mesh_uploads

    engine.CSMRenderEngine.view_draw = view_draw


def watch_first_person():
    """Wrap the first-person operator's start and end, so the driver knows when a key
    press started it and when Esc ended it (Blender 3.4 lists no running modal operators)."""
    from csm_engine.blender import operators
    cls = operators.CSM_OT_first_person
    original_invoke, original_finish = cls.invoke, cls._finish

    def invoke(self, context, event):
        result = original_invoke(self, context, event)
        if 'RUNNING_MODAL' in result:
            FIRST_PERSON["running"] = True
            FIRST_PERSON["invoked"] += 1
        return result

    def _finish(self, context):
        FIRST_PERSON["running"] = False
        return original_finish(self, context)

    cls.invoke, cls._finish = invoke, _finish


def region_rect(region):
    return {"x": region.x, "y": region.y, "width": region.width, "height": region.height}


def sidebar(area):
    return next((r for r in area.regions if r.type == 'UI'), None)


def window_with(area_type):
    """(window, area) of the first window showing an area of that type, or None."""
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == area_type:
                return window, area
    return None


def screen_height():
    if "screen_height" not in STATE:
        size = subprocess.run(["xdotool", "getdisplaygeometry"], check=True, timeout=10,
                              capture_output=True, text=True, stdin=subprocess.DEVNULL)
        STATE["screen_height"] = int(size.stdout.split()[1])
    return STATE["screen_height"]


def screen_top(window, region):
    """The region's top edge in X screen pixels. Blender counts window and region positions
    from the bottom-left: the window's from the screen's, the region's from the window's."""
    return screen_height() - window.y - (region.y + region.height)


def viewport_centre_on_screen():
    """The viewport's visible middle (left of the sidebar) in X screen pixels (top-left
    origin)."""
    window, area, region = STATE["window"], STATE["area"], STATE["region"]
    ui = sidebar(area)
    right = ui.x if ui is not None and ui.width > 1 and area.spaces.active.show_region_ui \
        else region.x + region.width
    return window.x + (region.x + right) // 2, screen_top(window, region) + region.height // 2


def screenshot(number, name, window=None, area=None):
    """Save a window's pixels (the main window by default) to <prefix>_<number>_<name>.png."""
    if window is None:
        window, area, region = STATE["window"], STATE["area"], STATE["region"]
    else:
        region = next(r for r in area.regions if r.type == 'WINDOW')
    path = os.path.join(SESSION["out_dir"], f"{SESSION['shot_prefix']}_{number}_{name}.png")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.screenshot(filepath=path, check_existing=False)
    if not os.path.isfile(path):
        raise RuntimeError(f"screen.screenshot did not write {path}")
    return os.path.basename(path)


def record(number, name, shot, **state):
    """One step's record in the report: its screenshot, the viewport's and the sidebar's
    rectangles (for cropping the screenshot), and what the driver saw."""
    entry = {"number": number, "name": name, "screenshot": shot, "draws": STATE["draws"],
             "seconds": round(time.monotonic() - STATE["started"], 3),
             "viewport_region": None, "sidebar_region": None, "sidebar_shown": False}
    area = STATE["area"]
    if area is not None:
        entry["viewport_region"] = region_rect(STATE["region"])
        ui = sidebar(area)
        shown = bool(area.spaces.active.show_region_ui)
        entry["sidebar_region"] = region_rect(ui) if ui is not None and shown else None
        entry["sidebar_shown"] = shown
    entry.update(state)
    REPORT["steps"].append(entry)
    log(f"step {number} {name}: {shot}")


# --- X events -----------------------------------------------------------------------------

def xdotool(*args):
    subprocess.run(["xdotool", *[str(a) for a in args]], check=True, timeout=10,
                   stdin=subprocess.DEVNULL)


# Where shared controls are drawn in the drivers' fixed 1600x900 window at the default UI
# scale (measured on the screenshots).
ADDON_CHECKBOX_FROM_LEFT_PX = 44  # Preferences > Add-ons: the first listed add-on's checkbox
ADDON_CHECKBOX_FROM_TOP_PX = 75
RENDER_TAB_FROM_TOP_PX = 62   # Properties editor: the Render tab, second icon of its tab column
ENGINE_FIELD_FROM_TOP_PX = 54  # Render properties: the Render Engine dropdown, under the "Scene" path
PIE_REACH_PX = 130           # how far up the mouse moves to the Z pie's top item


def enable_listed_addon(number, shot_name):
    """Preferences > Add-ons, with CSM the one add-on listed: click its checkbox, take
    screenshot ``shot_name`` of the Preferences window once csm_engine is enabled, close
    the window. A scenario step (``shot = yield from ...``) that returns the screenshot."""
    prefs_window, prefs_area = window_with('PREFERENCES')
    prefs_main = next(r for r in prefs_area.regions if r.type == 'WINDOW')
    yield from click_in(prefs_window, prefs_main, ADDON_CHECKBOX_FROM_LEFT_PX,
                        ADDON_CHECKBOX_FROM_TOP_PX)
    yield until("a click on the add-on's checkbox enabled csm_engine",
                lambda: "csm_engine" in bpy.context.preferences.addons)
    yield pause(0.5)
    shot = screenshot(number, shot_name, prefs_window, prefs_area)
    with bpy.context.temp_override(window=prefs_window):
        bpy.ops.wm.window_close()
    yield until("the Preferences window closed", lambda: window_with('PREFERENCES') is None)
    return shot


def open_render_engine_menu(window):
    """Click the Properties editor's Render tab, then its Render Engine dropdown; the
    caller picks the engine. A scenario step (``yield from ...``)."""
    properties = next(a for a in window.screen.areas if a.type == 'PROPERTIES')
    tabs = next(r for r in properties.regions if r.type == 'NAVIGATION_BAR')
    yield from click_in(window, tabs, tabs.width // 2, RENDER_TAB_FROM_TOP_PX)
    yield until("a click on the Render tab of the Properties editor",
                lambda: properties.spaces.active.context == 'RENDER')
    yield pause(0.3)
    settings = next(r for r in properties.regions if r.type == 'WINDOW')
    yield from click_in(window, settings, settings.width * 3 // 4, ENGINE_FIELD_FROM_TOP_PX)
    yield pause(0.5)


def set_for_screenshots(scene, area):
    """Set by script, not clicked: pictures that compare pixel for pixel (1600x900, no
    dither, Standard view transform) and a clean 3D viewport ``area`` (no overlays,
    gizmos, toolbar or tool header). Returns its space."""
    scene.render.resolution_x, scene.render.resolution_y = 1600, 900
    scene.render.dither_intensity = 0.0
    scene.view_settings.view_transform = 'Standard'
    scene.view_settings.look = 'None'
    space = area.spaces.active
    space.overlay.show_overlays = False
    space.show_gizmo = False
    space.show_region_toolbar = False
    space.show_region_tool_header = False
    return space


def rendered_shading_from_pie(space):
    """Rendered shading the way a user picks it: Z over the viewport opens the shading
    pie, and "Rendered" is its top item (the pie lays the enum out west, east, south,
    north). A scenario step (``yield from ...``)."""
    x, y = mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "z")
    yield pause(0.4)
    xdotool("mousemove", x, y - PIE_REACH_PX)
    yield pause(0.3)
    xdotool("click", "1")
    yield until("the Z pie switched the viewport to Rendered",
                lambda: space.shading.type == 'RENDERED')


HOLD_W_S = 0.5               # how long first person's W is held


def fly_forward(what):
    """Shift+F over the viewport starts the first-person camera (``what`` names it in the
    wait), then W is held for HOLD_W_S and the viewport draws the view it flew to. A
    scenario step (``yield from fly_forward(...)``)."""
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "shift+f")
    yield until(f"Shift+F started {what}", lambda: FIRST_PERSON["running"])
    yield fresh_draws(1)
    xdotool("keydown", "w")
    yield pause(HOLD_W_S)
    xdotool("keyup", "w")
    yield pause(0.3)
    yield fresh_draws(1)


def mouse_to_viewport():
    x, y = viewport_centre_on_screen()
    xdotool("mousemove", x, y)
    return x, y


def click_in(window, region, x, y):
    """Move the mouse to (x, y) pixels from the region's top-left corner and click; a
    scenario step (``yield from click_in(...)``)."""
    xdotool("mousemove", window.x + region.x + x, screen_top(window, region) + y)
    yield pause(0.2)
    xdotool("click", "1")


def menu_search(text):
    """F3 over the viewport (menu search) and ``text`` typed; the caller presses Enter.
    A scenario step (``yield from menu_search(...)``)."""
    mouse_to_viewport()
    yield pause(0.2)
    xdotool("key", "F3")
    yield pause(0.5)
    xdotool("type", "--delay", 20, text)
    yield pause(0.6)


# --- waiting ------------------------------------------------------------------------------

def until(name, condition):
    """Yielded by the scenario: resume once ``condition()`` is true."""
    return name, condition


def pause(seconds):
    end = time.monotonic() + seconds
    return until(f"{seconds} s pause", lambda: time.monotonic() >= end)


def fresh_draws(count=2):
    """A condition: the viewport drew ``count`` more complete frames from now on."""
    mark = STATE["draws"]

    def drawn():
        if STATE["draws"] - mark >= count:
            return True
        STATE["area"].tag_redraw()
        return False
    return until(f"{count} viewport draws", drawn)


def run(scenario, error_state=None):
    """Run the scenario from a timer; on failure record the traceback, a screenshot and
    ``error_state()`` (what the window showed), then end the session."""

    def tick():
        try:
            if STATE["draw_error"]:
                raise RuntimeError("the CSM viewport draw failed:\n" + STATE["draw_error"])
            now = time.monotonic()
            if now - STATE["started"] > TOTAL_LIMIT_S:
                raise RuntimeError(f"gave up after {TOTAL_LIMIT_S} s")
            if STATE["condition"] is not None and not STATE["condition"]():
                if now - STATE["condition_since"] > WAIT_LIMIT_S:
                    raise RuntimeError(f"waited {WAIT_LIMIT_S} s for: {STATE['condition_name']}")
                return TICK_S
            try:
                name, condition = next(scenario)
            except StopIteration:
                finish(0)
                return None
            STATE.update(condition=condition, condition_name=name, condition_since=now)
            return TICK_S
        except Exception:
            REPORT["error"] = traceback.format_exc()
            print(REPORT["error"], file=sys.stderr, flush=True)
            try:   # what the window showed when it went wrong, for the failure message
                REPORT["error_screenshot"] = screenshot(0, "error")
                if error_state is not None:
                    REPORT["error_state"] = error_state()
            except Exception:
                pass
            finish(1)

    bpy.app.timers.register(tick, first_interval=0.5)
