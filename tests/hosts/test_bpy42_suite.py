"""The window-less suite on pip bpy 4.2 LTS as well as 5.0.

``tests/bpy`` (registration, settings and their tooltips, operators, keymap entries, undo,
scene import, shader errors, renders checked by pixels, the benchmark and report tools)
runs in-process on pip bpy 5.0 with the rest of ``./dev test``; here the same files run
again in a subprocess of the bpy 4.2 interpreter, the oldest Blender the extension
supports. A failure shows pytest's own report from 4.2.
"""

import os
import re
import subprocess

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.hosts
SUITE_TIMEOUT_S = 900


def test_window_less_suite_passes_on_pip_bpy_4_2(hosts):
    python = hosts.bpy42_python()
    version = subprocess.run([python, "-c", "import bpy; print(bpy.app.version_string)"],
                             capture_output=True, text=True, timeout=120,
                             stdin=subprocess.DEVNULL)
    assert version.stdout.strip().startswith("4.2"), version.stdout + version.stderr[-2000:]
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    proc = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           os.path.join("tests", "bpy")],
                          cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=SUITE_TIMEOUT_S, stdin=subprocess.DEVNULL)
    report = proc.stdout[-6000:] + proc.stderr[-2000:]
    assert proc.returncode == 0, f"tests/bpy failed on pip bpy 4.2:\n{report}"
    summary = proc.stdout.strip().splitlines()[-1]
    passed = re.search(r"(\d+) passed", summary)
    assert passed and int(passed.group(1)) >= 100, summary
    assert not re.search(r"\d+ (failed|error|skipped)", summary), summary
