"""Helpers for the host tests: find each Blender host, give it throwaway user folders, run
scripts in it as a subprocess and read back what it reported and rendered.

The hosts are the ones a user has: pip bpy 5.0 (this interpreter, ``.venv``), pip bpy 4.2
(``$CSM_BPY42_PYTHON``, by default ``<repo>/.venv-bpy42``) and Debian's Blender 3.4
(``$CSM_BLENDER``, by default ``blender`` on PATH). ``./dev test`` sets all of them up.
A missing host is a test failure that says how to get it, never a skip.

Every host runs in a fresh subprocess whose Blender user folders (config, scripts,
extensions) point into a temporary directory, so the user's real Blender setup is never
read or written and each test starts from a clean install.
"""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import REPO
RESULT_PREFIX = "CSM_RESULT "
HOST_TIMEOUT_S = 600


def _check_interpreter(python, what, how_to_get):
    if not python or not os.path.isfile(python) or not os.access(python, os.X_OK):
        pytest.fail(f"{what} host not found (looked for {python!r}): {how_to_get}", pytrace=False)
    return python


def bpy50_python():
    """Interpreter with pip bpy 5.0: $CSM_BPY50_PYTHON, else the one running pytest."""
    return _check_interpreter(
        os.environ.get("CSM_BPY50_PYTHON") or sys.executable, "pip bpy 5.0",
        "run the tests with ./dev test, or set CSM_BPY50_PYTHON")


def bpy42_python():
    """Interpreter with pip bpy 4.2: $CSM_BPY42_PYTHON, else <repo>/.venv-bpy42."""
    return _check_interpreter(
        os.environ.get("CSM_BPY42_PYTHON") or os.path.join(REPO, ".venv-bpy42", "bin", "python"),
        "pip bpy 4.2", "run ./dev test (it creates .venv-bpy42 from requirements-bpy42.txt), "
        "or set CSM_BPY42_PYTHON to a Python 3.11 with bpy 4.2")


def blender_binary():
    """Debian's Blender 3.4: $CSM_BLENDER, else `blender` on PATH."""
    return _check_interpreter(
        os.environ.get("CSM_BLENDER") or shutil.which("blender"), "Debian Blender 3.4",
        "apt-get install blender (./dev test does this as root), or set CSM_BLENDER")


def extension_tool():
    """Blender's own extension tool, shipped inside pip bpy 5.0."""
    script = ("import bpy, os; print(os.path.join(bpy.utils.system_resource('SCRIPTS'), "
              "'addons_core', 'bl_pkg', 'cli', 'blender_ext.py'))")
    result = subprocess.run([bpy50_python(), "-c", script], capture_output=True, text=True,
                            timeout=HOST_TIMEOUT_S)
    path = result.stdout.strip().splitlines()[-1] if result.stdout.strip() else ""
    if result.returncode != 0 or not os.path.isfile(path):
        pytest.fail(f"Blender's extension tool not found in pip bpy 5.0:\n{result.stderr[-2000:]}",
                    pytrace=False)
    return path


def user_dirs_env(root):
    """Environment for a host whose Blender user folders all live under ``root``."""
    env = dict(os.environ)
    # The installed archive must be what runs, never the checkout.
    env.pop("PYTHONPATH", None)
    env.pop("PYTHONHOME", None)
    env.pop("PYTHONSTARTUP", None)
    for name, folder in (("BLENDER_USER_RESOURCES", "resources"), ("BLENDER_USER_CONFIG", "config"),
                         ("BLENDER_USER_SCRIPTS", "scripts"), ("BLENDER_USER_DATAFILES", "datafiles"),
                         ("BLENDER_USER_EXTENSIONS", "extensions")):
        env[name] = os.path.join(root, "blender-user", folder)
        os.makedirs(env[name], exist_ok=True)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


class HostRun:
    """What one host subprocess did: exit code, output, and its ``CSM_RESULT`` JSON."""

    def __init__(self, command, completed):
        self.command = command
        self.returncode = completed.returncode
        self.output = completed.stdout + completed.stderr
        self.result = {}
        for line in completed.stdout.splitlines():
            if line.startswith(RESULT_PREFIX):
                self.result = json.loads(line[len(RESULT_PREFIX):])

    def describe(self):
        tail = "\n".join(self.output.strip().splitlines()[-40:])
        return f"command: {' '.join(self.command)}\nexit code: {self.returncode}\noutput (tail):\n{tail}"


def run_host(command, env, cwd):
    """Run one host command; cwd should be a temporary folder so the checkout is not on
    sys.path. Never raises for a failing host: the caller asserts on the HostRun."""
    try:
        completed = subprocess.run(command, env=env, cwd=cwd, capture_output=True, text=True,
                                   stdin=subprocess.DEVNULL, timeout=HOST_TIMEOUT_S)
    except subprocess.TimeoutExpired as error:
        pytest.fail(f"host timed out after {HOST_TIMEOUT_S} s: {' '.join(command)}\n"
                    f"{(error.stdout or b'')[-2000:]!r}", pytrace=False)
    return HostRun(command, completed)


HOST_NAMES = ("blender 3.4", "bpy 4.2", "bpy 5.0")


def script_command(host, script, *args):
    """The command that runs a Python ``script`` with ``args`` in one of HOST_NAMES."""
    if host == "blender 3.4":
        return [blender_binary(), "-b", "--factory-startup", "--python", script, "--", *args]
    python = bpy42_python() if host == "bpy 4.2" else bpy50_python()
    return [python, script, *args]


def copy_package(work):
    """A copy of the checkout's ``csm_engine`` package (data inside) and of its GLSL
    library ``shaders/`` beside it, as in the checkout, in ``work``, for host scripts that
    put ``work`` on sys.path; returns the package's path."""
    import shutil
    target = os.path.join(str(work), "csm_engine")
    shutil.copytree(os.path.join(REPO, "csm_engine"), target,
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(os.path.join(REPO, "shaders"), os.path.join(str(work), "shaders"))
    return target


def run_script_with_package(host, host_dir, script_text, *args):
    """Run ``script_text`` in one of HOST_NAMES with a copy of the package in
    ``host_dir/work`` (its first argument) and throwaway Blender user folders."""
    work = os.path.join(str(host_dir), "work")
    copy_package(work)
    script = os.path.join(str(host_dir), "host_script.py")
    with open(script, "w", encoding="utf-8") as handle:
        handle.write(script_text)
    command = script_command(host, script, work, *args)
    return run_host(command, user_dirs_env(str(host_dir)), str(host_dir))


def read_png(path):
    """PNG -> float array (height, width, channels) in 0..1, top row first (the one PNG
    reader, ``csm_tools.report_io``, with no imaging library beyond numpy)."""
    from csm_tools.report_io import read_png as read_png_samples
    samples = read_png_samples(path)
    return samples.astype(np.float64) / (65535.0 if samples.dtype == np.uint16 else 255.0)


def luminance(image):
    rgb = image[..., :3] if image.shape[-1] >= 3 else np.repeat(image[..., :1], 3, axis=-1)
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture
def host_dir(tmp_path):
    """A clean working folder for one host run, with throwaway Blender user folders."""
    return tmp_path


@pytest.fixture(scope="session")
def hosts():
    """These helpers as one object, so tests never `import conftest` (several test folders
    have a conftest.py, and that import would pick whichever was loaded last)."""
    return _THIS_MODULE


# Captured at import: sys.modules["conftest"] is rebound when another folder's conftest loads.
_THIS_MODULE = sys.modules[__name__]
