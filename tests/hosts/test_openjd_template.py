"""The Open Job Description template farm/openjd/csm-render.yaml, as a farm runs it:
``openjd check`` accepts it, and ``openjd run`` renders a two-frame chunk of a .blend with
CSM, through ``blender -b FILE.blend -E CSM ... -a`` in Debian's Blender 3.4 (the legacy
add-on installed and enabled the way the docs tell a worker's admin to) and through
``python -m csm_engine ... --workers 0`` on pip bpy 5.0. The frames must be the moving
camera's lit landscape: two different, sunlit and shadowed pictures.
"""
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from tests.conftest import REPO
from tests.hosts.test_packaging import _manifest, _run_build

pytestmark = pytest.mark.hosts

TEMPLATE = os.path.join(REPO, "farm", "openjd", "csm-render.yaml")
OPENJD = os.path.join(os.path.dirname(sys.executable), "openjd")
# Made in the host itself (a .blend is read by its own Blender version and later ones).
DEMO_SCRIPT = """
import sys, bpy
from csm_engine.blender import cli
scene = cli.open_scene("default", resolution=(96, 54))
camera = scene.camera
start = camera.location.copy()
side = camera.matrix_world.to_3x3().col[0]
for frame, shift in ((1, 0.0), (2, 40.0)):
    camera.location = start + side * shift
    camera.keyframe_insert("location", frame=frame)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])
"""


def openjd(*args, env=None, cwd=None):
    return subprocess.run([OPENJD, *args], capture_output=True, text=True, timeout=600,
                          env=env, cwd=cwd, stdin=subprocess.DEVNULL)


def assert_two_frames_of_the_flight(folder, hosts):
    names = sorted(os.listdir(folder))
    assert names == ["f_0001.png", "f_0002.png"], names
    first, second = (hosts.read_png(str(folder / name)) for name in names)
    for image in (first, second):
        light = hosts.luminance(image)
        assert np.percentile(light, 90) > 0.3, "sunlit ground"
        assert (light < 0.5 * np.percentile(light, 90)).mean() > 0.05, "and shadows"
    assert np.abs(first - second).mean() > 0.02, "the camera moved between the frames"


def test_openjd_check_accepts_the_template():
    result = openjd("check", TEMPLATE)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "passes validation" in result.stdout


def test_openjd_run_renders_two_frames_with_blender_and_the_installed_add_on(
        hosts, tmp_path):
    blender = hosts.blender_binary()
    env = hosts.user_dirs_env(str(tmp_path))
    dist = tmp_path / "dist"
    built = _run_build(REPO, str(dist))
    assert built.returncode == 0, built.stdout + built.stderr
    legacy = dist / f"csm_engine-{_manifest()['version']}-legacy.zip"
    with zipfile.ZipFile(legacy) as archive:
        archive.extractall(os.path.join(env["BLENDER_USER_SCRIPTS"], "addons"))
    # What a worker's admin does once: enable the add-on and save the preferences.
    enable = hosts.run_host([blender, "-b", "--python-expr",
                             "import bpy; bpy.ops.preferences.addon_enable(module='csm_engine');"
                             " bpy.ops.wm.save_userpref()"], env, str(tmp_path))
    assert enable.returncode == 0, enable.describe()
    script = tmp_path / "make_demo.py"
    script.write_text(DEMO_SCRIPT)
    blend = tmp_path / "flight.blend"
    made = hosts.run_host([blender, "-b", "--python", str(script), "--", str(blend)], env,
                          str(tmp_path))
    assert made.returncode == 0 and blend.is_file(), made.describe()
    frames = tmp_path / "frames"
    result = openjd("run", TEMPLATE, "-p", f"BlendFile={blend}", "-p", f"OutputDir={frames}",
                    "-p", "FirstFrame=1", "-p", "LastFrame=2", "-p", "ChunkSize=2",
                    "-p", f"BlenderExecutable={blender}", env=env, cwd=str(tmp_path))
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "engine not found" not in result.stdout, "CSM was not enabled in the worker"
    assert "Chunks run: 1" in result.stdout, result.stdout[-4000:]
    assert_two_frames_of_the_flight(frames, hosts)


def test_openjd_run_renders_two_frames_with_python_on_pip_bpy(hosts, tmp_path):
    python = hosts.bpy50_python()
    env = hosts.user_dirs_env(str(tmp_path))
    env["PYTHONPATH"] = REPO        # the checkout stands in for `pip install csm_engine`
    script = tmp_path / "make_demo.py"
    script.write_text(DEMO_SCRIPT)
    blend = tmp_path / "flight.blend"
    made = hosts.run_host([python, str(script), str(blend)], env, str(tmp_path))
    assert made.returncode == 0 and blend.is_file(), made.describe()
    frames = tmp_path / "frames"
    result = openjd("run", TEMPLATE, "-p", f"BlendFile={blend}", "-p", f"OutputDir={frames}",
                    "-p", "FirstFrame=1", "-p", "LastFrame=2", "-p", "ChunkSize=1",
                    "-p", "Renderer=python", "-p", f"PythonExecutable={python}",
                    env=env, cwd=str(tmp_path))
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert_two_frames_of_the_flight(frames, hosts)
