"""``./dev shader-ab`` renders a benchmark camera animation with two GLSL folders, frame
by frame, and prints each pass's median for both and their ratio. Times are not asserted
(machines vary)."""
import re

import pytest

from tests.bpy.tools.tool_helpers import run_module
from tests.conftest import REPO


# Speed is measured and published on the main host (bpy 5.0) only.
pytestmark = pytest.mark.benchmark


def test_two_folders_are_timed_pass_by_pass(tmp_path):
    shaders = f"{REPO}/shaders"
    proc = run_module("shader_ab", "default", shaders, shaders, "--frames", "2",
                      "--resolution", "160x90", cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = dict((m[0], (float(m[1]), float(m[2])))
                for m in re.findall(r"^(\w+) +([0-9.]+) +([0-9.]+) +[0-9.]+$", proc.stdout,
                                    re.M))
    assert {"shadow", "gbuffer", "lighting", "fxaa", "wall"} <= set(rows), proc.stdout
    assert all(a > 0 and b > 0 for a, b in (rows["lighting"], rows["wall"]))


def test_a_folder_without_shaders_is_one_clear_line(tmp_path):
    proc = run_module("shader_ab", "default", tmp_path, f"{REPO}/shaders", cwd=tmp_path,
                      timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip() == (f"shader A/B: error: FOLDER_A: '{tmp_path}' is not a "
                                   "GLSL folder (no lighting_frag.glsl)")
