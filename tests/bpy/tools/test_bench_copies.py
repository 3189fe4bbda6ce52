"""The copies benchmark writes scenes of many references to one mesh file (and to several)
and reports, per scene, a command-line render's wall time and peak memory, and a picture.
Times are not asserted (machines vary)."""
import json
import os

import pytest

from csm_engine.core import scene_format
from tests.bpy.tools.tool_helpers import run_module


# Speed is measured and published on the main host (bpy 5.0) only.
pytestmark = pytest.mark.benchmark


def test_copies_scenes_reference_each_file_as_asked(tmp_path):
    from csm_tools.bench_copies import write_scene
    path = write_scene(str(tmp_path), 20, distinct=2)
    objects = scene_format.load_scene(path).objects
    meshes = [os.path.basename(o.mesh) for o in objects]
    assert meshes.count("ground.obj") == 1
    assert meshes.count("box0.obj") == meshes.count("box1.obj") == 20
    assert sum(o.scale.x < 0 for o in objects) == 6        # every seventh mirrored


def test_the_benchmark_renders_each_scene_and_reports_time_and_memory(tmp_path):
    proc = run_module("bench_copies", "--sizes", "30", "--distinct", "2x10", "--no-eevee",
                      "--folder", tmp_path, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    assert [(r["files"], r["copies"]) for r in rows] == [(1, 30), (2, 10)]
    for row in rows:
        assert row["csm_s"] > 0 and row["csm_mb"] > 100 and os.path.getsize(row["png"]) > 0


def test_a_bad_size_is_one_clear_message(tmp_path):
    for args in (("--sizes", "many"), ("--distinct", "10by100"), ("--sizes", "0")):
        proc = run_module("bench_copies", *args, cwd=tmp_path, timeout=60)
        assert proc.returncode == 2, args
        assert args[1] in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
        assert not proc.stdout, args          # nothing was rendered
