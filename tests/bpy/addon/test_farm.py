"""The animation farm (``python -m csm_engine FILE.blend --frames ... --workers N``), run
as a user runs it, in subprocesses of this interpreter (pip bpy 5.0 and dask.distributed).

The reference is this process rendering the same .blend's frames one by one, backwards:
every frame the farm writes must be pixel-identical to it, whichever worker rendered
which frames before. The demo .blend is made here from the bundled default scene with a
moving camera (tiny frames: the farm, not the picture, is under test).
"""
import os
import subprocess
import sys

import bpy
import numpy as np
import pytest

from csm_engine.blender import cli, engine
from csm_engine.farm import worker
from tests.bpy.bpy_helpers import load_png
from tests.conftest import REPO

FRAMES = range(1, 9)
NAMES = [f"f_{frame:04d}.png" for frame in FRAMES]


def run_farm(args, cwd, **env):
    environment = dict(os.environ, PYTHONPATH=REPO, **env)
    return subprocess.run([sys.executable, "-m", "csm_engine", *args], cwd=cwd,
                          env=environment, capture_output=True, text=True, timeout=300)


def farm(blend, folder, workers, *extra, **env):
    result = run_farm([str(blend), "--frames", "1-8", "--output",
                       str(folder / "f_####.png"), "--workers", str(workers), *extra],
                      cwd=folder.parent, **env)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    return result


def make_demo_blend(path):
    """The default scene at 96x54 with its camera flying 40 m sideways and 20 m closer
    over frames 1-8 (so every frame's shadow cascades are fitted anew), two render
    samples (jittered cameras) and Fit to View on, the settings whose state could carry
    from one frame to the next."""
    scene = cli.open_scene("default", resolution=(96, 54))
    scene.render.engine = "CSM"
    scene.csm.render_samples = 2
    scene.csm.fit_to_visible = True
    camera = scene.camera
    start = camera.location.copy()
    side = camera.matrix_world.to_3x3().col[0]
    forward = -camera.matrix_world.to_3x3().col[2]
    scene.frame_start, scene.frame_end = FRAMES[0], FRAMES[-1]
    for frame in (FRAMES[0], FRAMES[-1]):
        t = (frame - FRAMES[0]) / (FRAMES[-1] - FRAMES[0])
        camera.location = start + side * (40.0 * t) + forward * (20.0 * t)
        camera.keyframe_insert("location", frame=frame)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """(demo .blend, folder of reference frames rendered in this process, last to first)."""
    folder = tmp_path_factory.mktemp("farm")
    blend = folder / "demo.blend"
    make_demo_blend(blend)
    reference = folder / "reference"
    reference.mkdir()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    scene.render.image_settings.file_format = 'PNG'
    scene.render.image_settings.color_mode = 'RGB'
    for frame in reversed(FRAMES):
        scene.frame_set(frame)
        result = engine.render_final(scene)
        assert result.error is None, result.error
        cli.write_render_png(scene, str(reference / f"f_{frame:04d}.png"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return blend, reference


@pytest.fixture(scope="module")
def two_workers(demo):
    blend, reference = demo
    folder = reference.parent / "two_workers"
    result = farm(blend, folder, 2)
    return folder, result


def pixels(folder):
    return [load_png(str(folder / name)) for name in NAMES]


def rendering_workers(output):
    return {line.split("(worker ")[1].split(")")[0].split(",")[0]
            for line in output.splitlines() if "(worker " in line}


def test_two_workers_write_exactly_the_frames_identical_to_one_worker_and_one_process(
        demo, two_workers):
    blend, reference = demo
    folder, result = two_workers
    assert sorted(os.listdir(folder)) == NAMES, "exactly the frames, no temporary files"
    assert len(rendering_workers(result.stdout)) == 2, result.stdout
    one = reference.parent / "one_worker"
    farm(blend, one, 1)
    assert sorted(os.listdir(one)) == NAMES
    expected = pixels(reference)
    for name, two, single, ref in zip(NAMES, pixels(folder), pixels(one), expected):
        assert np.array_equal(two, ref), f"{name}: 2 workers differ from one process"
        assert np.array_equal(single, ref), f"{name}: 1 worker differs from one process"
    # The frames are the animation's, not one picture eight times: the camera moved.
    assert expected[0].std() > 0.05
    assert np.abs(expected[0] - expected[-1]).mean() > 0.02


def test_a_second_run_renders_nothing_and_a_missing_frame_is_rendered_alone(demo,
                                                                             two_workers):
    blend, reference = demo
    folder, _ = two_workers
    before = {name: os.stat(folder / name).st_mtime_ns for name in NAMES}
    again = farm(blend, folder, 2)
    assert "all 8 frames are there already" in again.stdout, again.stdout
    assert {name: os.stat(folder / name).st_mtime_ns for name in NAMES} == before
    os.remove(folder / "f_0005.png")
    resumed = farm(blend, folder, 2)
    assert "rendering 1 of 8 frames" in resumed.stdout, resumed.stdout
    assert sorted(os.listdir(folder)) == NAMES
    assert {name: os.stat(folder / name).st_mtime_ns for name in NAMES
            if name != "f_0005.png"} == {k: v for k, v in before.items() if k != "f_0005.png"}
    assert np.array_equal(load_png(str(folder / "f_0005.png")),
                          load_png(str(reference / "f_0005.png")))


def test_a_worker_that_dies_mid_frame_has_its_frame_rendered_by_another(demo, tmp_path):
    blend, reference = demo
    marker = tmp_path / "a worker died"
    folder = tmp_path / "frames"
    result = farm(blend, folder, 2, **{worker.CRASH_ONCE_ENV: str(marker)})
    assert marker.exists(), "the hook made one worker exit mid-frame"
    assert sorted(os.listdir(folder)) == NAMES
    # Every frame reported written once, the dead worker's one by another process.
    assert result.stdout.count("] wrote ") == len(NAMES), result.stdout
    for name, got, ref in zip(NAMES, pixels(folder), pixels(reference)):
        assert np.array_equal(got, ref), name


def test_workers_0_renders_in_its_own_process_without_dask(demo, tmp_path):
    blend, reference = demo
    folder = tmp_path / "frames"
    result = run_farm([str(blend), "--frames", "7-8", "--output", str(folder / "f_####.png"),
                       "--workers", "0"], cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "in this process" in result.stdout
    assert sorted(os.listdir(folder)) == NAMES[6:]
    for name in NAMES[6:]:
        assert np.array_equal(load_png(str(folder / name)), load_png(str(reference / name)))


@pytest.mark.parametrize("args, message", [
    (["missing.blend", "--frames", "1-8", "--output", "f_####.png"], "no such file"),
    (["{blend}", "--frames", "8-1", "--output", "f_####.png"], "ends before it starts"),
    (["{blend}", "--frames", "1-x", "--output", "f_####.png"], "is not a frame or a range"),
    (["{blend}", "--frames", "1-8", "--output", "frames.png"], "has no # in its file name"),
    (["{blend}", "--frames", "1-8", "--output", "f_####.jpg"], "end the name with .png"),
    (["{blend}", "--frames", "1-8", "--output", "f_####.png", "--workers", "-1"],
     "--workers: -1 is outside"),
    (["{blend}", "--frames", "1-8", "--output", "f_####.png", "--set", "nope=1"],
     "unknown setting 'nope'"),
    (["{json}", "--frames", "1-8", "--output", "f_####.png"], "not a .blend file"),
])
def test_a_mistake_is_one_line_and_renders_nothing(demo, tmp_path, args, message):
    blend, _ = demo
    fake = tmp_path / "scene.blend"
    fake.write_text("{}")
    args = [a.format(blend=blend, json=fake) for a in args]
    result = run_farm(args, cwd=tmp_path)
    assert result.returncode in (cli.EXIT_USAGE, cli.EXIT_SCENE), result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert not list(tmp_path.glob("f_*")), "nothing was written"


@pytest.mark.parametrize("workers", ["0", "1"])
def test_a_file_that_cannot_be_opened_is_said_once_not_per_frame(demo, tmp_path, workers):
    blend, _ = demo
    broken = tmp_path / "broken.blend"
    broken.write_bytes(blend.read_bytes()[:4096])      # a .blend cut short: valid header
    result = run_farm([str(broken), "--frames", "1-4", "--output",
                       str(tmp_path / "f_####.png"), "--workers", workers], cwd=tmp_path)
    assert result.returncode == cli.EXIT_RENDER, result.stdout + result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("csm: error:")]
    assert len(errors) == 2, result.stderr
    assert "broken.blend" in errors[0]
    assert errors[1].startswith("csm: error: 4 of 4 frames were not written (1, 2, 3, 4)")
    assert "Traceback" not in result.stderr
    assert not list(tmp_path.glob("f_*")), "nothing was written"


def test_without_dask_one_line_says_how_to_install_it(demo, tmp_path):
    blend, _ = demo
    shadow = tmp_path / "no_dask"
    shadow.mkdir()
    (shadow / "distributed.py").write_text("raise ImportError('no dask here')\n")
    result = subprocess.run(
        [sys.executable, "-m", "csm_engine", str(blend), "--frames", "1-2", "--output",
         str(tmp_path / "f_##.png")], cwd=tmp_path, capture_output=True, text=True,
        env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(shadow), REPO])), timeout=60)
    assert result.returncode == 7, result.stderr
    assert result.stderr.count("\n") == 1 and "pip install csm_engine[farm]" in result.stderr


def test_freeze_cascades_holds_the_first_frames_cascades_in_every_worker(demo, tmp_path):
    """With Freeze Cascades every frame shows the cascades fitted at the range's first
    frame, as ``blender -a`` over the range does, whichever frame a worker starts with."""
    blend, reference = demo
    expected = tmp_path / "in_order"
    expected.mkdir()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    scene.csm.freeze_cascades = True
    scene.render.image_settings.file_format = 'PNG'
    scene.render.image_settings.color_mode = 'RGB'
    engine.forget_final_render_view()
    for frame in FRAMES:
        scene.frame_set(frame)
        assert engine.render_final(scene).error is None
        cli.write_render_png(scene, str(expected / f"f_{frame:04d}.png"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    engine.forget_final_render_view()
    folder = tmp_path / "frames"
    farm(blend, folder, 2, "--set", "freeze_cascades=on")
    frozen = pixels(expected)
    assert not np.array_equal(frozen[-1], load_png(str(reference / NAMES[-1]))), \
        "freezing changes the last frame (else this test shows nothing)"
    for name, got, want in zip(NAMES, pixels(folder), frozen):
        assert np.array_equal(got, want), name
