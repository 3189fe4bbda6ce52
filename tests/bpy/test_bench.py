"""The benchmark command runs end to end in quick mode and reports what docs/benchmarks.md
publishes: CSM and EEVEE frame times per scene, their ratio, CSM's per-pass split, and a
camera-only viewport redraw that uploads nothing. Times are not asserted (CI machines vary).

It runs in a subprocess: the benchmark resets the Blender session (factory settings) and
that must not disturb the other tests' shared bpy state.
"""
import json
import os
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_quick_benchmark_reports_both_engines_and_a_free_camera_redraw(tmp_path):
    out = tmp_path / "bench.json"
    env = dict(os.environ, PYTHONPATH=REPO)
    proc = subprocess.run(
        [sys.executable, "-m", "csm_engine.bench", "--quick", "--json", str(out)],
        cwd=str(tmp_path), env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "EEVEE/CSM" in proc.stdout          # the printed table a user reads
    results = json.loads(out.read_text())

    assert [s["name"] for s in results["scenes"]] == ["default", "field"]
    for scene in results["scenes"]:
        assert scene["triangles"] > 1000, scene["name"]
        assert scene["csm"]["median_s"] > 0 and scene["eevee"]["median_s"] > 0
        assert scene["ratio"] == scene["eevee"]["median_s"] / scene["csm"]["median_s"]
        split = scene["csm_split_s"]
        for step in ("mesh_upload", "python_setup", "shadow", "gbuffer", "lighting",
                     "readback"):
            assert split[step] > 0, (scene["name"], step, split)
        viewport = scene["viewport"]
        assert viewport["camera_only_uploads"] == 0, scene["name"]
        assert viewport["redraws"] > 0 and viewport["python_overhead_ms_median"] > 0
        assert viewport["frame_ms_median"] >= viewport["python_overhead_ms_median"]
    # The field's monkeys each own their mesh: editing one re-uploads exactly one.
    field = results["scenes"][1]
    assert field["viewport"]["one_object_edit"]["uploads"] == 1

    scaling = results["scaling"]
    assert len(scaling) >= 2
    assert scaling[-1]["triangles"] > scaling[0]["triangles"]
    assert all(row["median_s"] > 0 and row["mesh_upload_mb"] > 0 for row in scaling)


def test_a_bad_resolution_is_one_clear_message(tmp_path):
    env = dict(os.environ, PYTHONPATH=REPO)
    proc = subprocess.run(
        [sys.executable, "-m", "csm_engine.bench", "--resolution", "wide"],
        cwd=str(tmp_path), env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "--resolution" in proc.stderr and "wide" in proc.stderr
    assert "Traceback" not in proc.stderr
