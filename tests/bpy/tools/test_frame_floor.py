"""``./dev frame-floor`` prints the least a full-screen pass and a pass of N triangles cost
on this machine (the floors docs/benchmarks.md sets against EEVEE's frame over 20). Times
are not asserted (machines vary)."""
import re

import pytest

from tests.bpy.tools.tool_helpers import run_module


# Speed is measured and published on the main host (bpy 5.0) only.
pytestmark = pytest.mark.benchmark


def test_frame_floor_prints_each_floor_in_milliseconds(tmp_path):
    proc = run_module("frame_budget", "--resolution", "160x90", "--triangles", "5000",
                      cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    found = dict(re.findall(r"^(.*): ([0-9.]+) ms$", proc.stdout, re.M))
    assert set(found) == {"160x90, a minimal full-screen pass",
                          "5,000 triangles, depth only",
                          "5,000 triangles, two colour targets",
                          "5,000 triangles, two colour targets and ten values",
                          "5,000 triangles, depth only, outside the view"}, proc.stdout
    assert all(float(v) > 0 for v in found.values())


def test_a_bad_triangle_count_is_one_clear_line(tmp_path):
    proc = run_module("frame_budget", "--triangles", "1", cwd=tmp_path, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "./dev frame-floor: --triangles: needs at least 2, got 1"
