"""The host half of the GUI tests: an X server, a Blender 3.4 window with a driver script
inside it, and the pictures it leaves.

Owns what ``test_gui_viewport.py``, ``test_gui_controls.py`` and
``test_gui_student_walk.py`` share: a fresh Xvfb, Blender's user folders without the splash
screen, the add-on's legacy zip, starting Blender with a driver (``gui_*driver.py``) and
reading its JSON report, decoding screenshots, and scaling them for docs/.
"""

import json
import os
import select
import shutil
import subprocess
import time

import pytest

from tests.conftest import REPO
from tests.hosts.test_packaging import _manifest, _run_build

SCREEN_SIZE = (1600, 900)
PREFERENCES_TIMEOUT_S = 120
DOCS_WIDTH_PX = 1200         # screenshots in docs/ are scaled to this width


def fail(message):
    pytest.fail(message, pytrace=False)


# --- processes ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def x_display():
    """A fresh Xvfb on a display number the server picks itself (-displayfd): no guessing,
    no clash with a display in use, and no sleep: the number arrives once it accepts clients."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        fail("Xvfb not found: apt-get install xvfb")
    read_end, write_end = os.pipe()
    width, height = SCREEN_SIZE
    server = subprocess.Popen(
        [xvfb, "-displayfd", str(write_end), "-screen", "0", f"{width}x{height}x24",
         "-nolisten", "tcp", "-noreset"],
        pass_fds=[write_end], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE)
    os.close(write_end)
    number = b""
    deadline = time.monotonic() + 30
    while not number.endswith(b"\n") and time.monotonic() < deadline:
        ready, _, _ = select.select([read_end], [], [], 0.5)
        if ready:
            chunk = os.read(read_end, 64)
            if not chunk:
                break
            number += chunk
    os.close(read_end)
    if not number.strip().isdigit():
        server.kill()
        fail(f"Xvfb did not start: {server.communicate()[1].decode(errors='replace')[-2000:]}")
    try:
        yield ":" + number.strip().decode()
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()


def blender_env(hosts, root, display):
    env = hosts.user_dirs_env(str(root))
    env["DISPLAY"] = display
    return env


def save_preferences_without_splash(blender, env, cwd):
    """The splash screen covers the middle of the window; a throwaway userpref.blend turns it
    off before the GUI starts (it is read only at start-up)."""
    script = ("import bpy; bpy.context.preferences.view.show_splash = False; "
              "bpy.ops.wm.save_userpref()")
    done = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1",
                           "--python-expr", script], env=env, cwd=cwd, capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=PREFERENCES_TIMEOUT_S)
    prefs = os.path.join(env["BLENDER_USER_CONFIG"], "userpref.blend")
    if done.returncode != 0 or not os.path.isfile(prefs):
        fail(f"could not save Blender preferences without the splash screen:\n"
              f"{(done.stdout + done.stderr)[-3000:]}")


def fresh_blender(hosts, display, tmp_path_factory, name):
    """(blender, root, out_dir, env, legacy_zip) for one GUI test module: Blender 3.4 with
    fresh user folders whose preferences skip the splash screen, an empty folder for the
    driver's screenshots and report, and the add-on's legacy zip built from this tree."""
    if shutil.which("xdotool") is None:
        fail("xdotool not found: apt-get install xdotool")
    blender = hosts.blender_binary()
    root = tmp_path_factory.mktemp(name)
    out_dir = root / "out"
    out_dir.mkdir()
    env = blender_env(hosts, root, display)
    save_preferences_without_splash(blender, env, str(root))
    built = _run_build(REPO, str(root / "dist"))
    if built.returncode != 0:
        fail(f"tools/build.py failed:\n{built.stdout}{built.stderr}")
    legacy = root / "dist" / f"csm_engine-{_manifest()['version']}-legacy.zip"
    return blender, root, out_dir, env, legacy


def run_driver(blender, driver, args, env, root, report_name, timeout_s):
    """Blender's window (SCREEN_SIZE, at the screen's top-left) running ``driver`` with
    ``args``; returns (report, output, seconds). Fails the test, with the driver's error or
    Blender's last output, when Blender hangs, the driver writes no report or reports an
    error."""
    width, height = SCREEN_SIZE
    command = [blender, "--window-geometry", "0", "0", str(width), str(height),
               "--no-window-focus", "--python", driver, "--", *[str(a) for a in args]]
    started = time.monotonic()
    process = subprocess.Popen(command, env=env, cwd=str(root), stdin=subprocess.DEVNULL,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        output, _ = process.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
        fail(f"Blender did not finish within {timeout_s} s:\n{output[-4000:]}")
    seconds = time.monotonic() - started
    report_path = os.path.join(str(args[0]), report_name)
    if not os.path.isfile(report_path):
        fail(f"the driver wrote no report (exit code {process.returncode}):\n{output[-4000:]}")
    with open(report_path) as handle:
        report = json.load(handle)
    if report["error"] or process.returncode != 0:
        fail(f"the driver failed (exit code {process.returncode}):\n"
              f"{report['error'] or output[-4000:]}\nimages in {args[0]}")
    return report, output, seconds


def load_png(path):
    """PNG -> float32 (height, width, 3) in 0..1, top row first, decoded by pip bpy's image
    loader (a decoder independent of the Blender that wrote the file)."""
    from tests.bpy.bpy_helpers import load_png as load_with_blender
    return load_with_blender(path)[..., :3]


def save_for_docs(source, target):
    """A screenshot as docs/ keeps it: at most DOCS_WIDTH_PX wide, 256 colours without
    dithering (flat UI colours stay flat), under 200 KB."""
    done = subprocess.run(["convert", str(source), "-resize", f"{DOCS_WIDTH_PX}x>", "-strip",
                           "+dither", "-colors", "256", str(target)],
                          capture_output=True, text=True)
    assert done.returncode == 0, f"ImageMagick convert failed: {done.stderr}"
    assert os.path.getsize(target) < 200_000, (target, os.path.getsize(target))
