"""The course's command-line contract: scene in, PNG out, one-line errors.

Runs ``python -m csm_engine`` in a subprocess of this interpreter (pip bpy 5.0), and the
``blender -b -P csm_engine/blender_cli.py`` bridge on Debian's Blender 3.4.
"""
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from csm_engine.blender import cli
from tests.bpy.bpy_helpers import load_png
from tests.conftest import REPO

DEFAULT_SCENE = os.path.join(REPO, "csm_engine", "data", "scenes", "default.json")


def run_blender_cli(args, cwd):
    """``blender -b -P csm_engine/blender_cli.py -- args`` on Debian's Blender 3.4."""
    blender = os.environ.get("CSM_BLENDER") or shutil.which("blender")
    assert blender, "Debian's blender (3.4) is required: apt-get install blender"
    return subprocess.run(
        [blender, "-b", "--factory-startup", "-P",
         os.path.join(REPO, "csm_engine", "blender_cli.py"), "--", *args],
        capture_output=True, text=True, timeout=300, cwd=cwd)


def run_cli(args, cwd):
    env = dict(os.environ, PYTHONPATH=REPO)
    return subprocess.run([sys.executable, "-m", "csm_engine", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def assert_lit_landscape(pixels):
    rgb = pixels[..., :3]
    luminance = rgb @ np.array([0.2126, 0.7152, 0.0722])
    bright = np.percentile(luminance, 90)
    assert bright > 0.3, "a good part of the image is sunlit"
    assert (luminance < 0.5 * bright).mean() > 0.05, "and some of it is in shadow"
    green = (rgb[..., 1] > rgb[..., 0]) & (rgb[..., 1] > rgb[..., 2])
    assert green.mean() > 0.2, "the landscape's grass shows its texture colour"


def test_default_scene_to_png_at_the_requested_size(tmp_path):
    result = run_cli(["--resolution", "320x180"], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    shot = tmp_path / "csm_default.png"
    pixels = load_png(str(shot))
    assert pixels.shape == (180, 320, 4)
    assert_lit_landscape(pixels)


def test_scene_and_screenshot_arguments_and_overrides(tmp_path):
    shot = tmp_path / "cascades.png"
    result = run_cli([DEFAULT_SCENE, str(shot), "--resolution", "160x90",
                      "--set", "debug_view=CASCADES", "--set", "pcf_radius=2"], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    rgb = load_png(str(shot))[..., :3]
    # The landscape is green and brown; only the far cascade's tint makes pixels blue.
    blue = (rgb[..., 2] > rgb[..., 0] + 0.05) & (rgb[..., 2] > rgb[..., 1] + 0.05)
    assert blue.mean() > 0.2, "cascade colours tint the image"


@pytest.mark.parametrize("args, code, words", [
    (["missing.json"], 3, ["missing.json"]),
    (["bad.json"], 3, ["bad.json", "line"]),
    ([DEFAULT_SCENE, "out.png", "--set", "pcf_radius=99"], 2, ["pcf_radius", "99"]),
    ([DEFAULT_SCENE, "out.png", "--set", "nonsense=1"], 2, ["nonsense"]),
    ([DEFAULT_SCENE, "out.png", "--set", "split_scheme=SPIRAL"], 2, ["split_scheme", "SPIRAL"]),
    ([DEFAULT_SCENE, "out.png", "--resolution", "big"], 2, ["--resolution", "big"]),
    ([DEFAULT_SCENE, "no/such/folder/out.png"], 2, ["no/such/folder"]),
])
def test_user_mistakes_give_one_line_and_a_nonzero_exit(tmp_path, args, code, words):
    (tmp_path / "bad.json").write_text('{"objects": [ }')
    result = run_cli(args, cwd=tmp_path)
    assert result.returncode == code, (result.returncode, result.stderr)
    errors = [line for line in result.stderr.splitlines() if line.startswith("csm: error:")]
    assert len(errors) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert not (tmp_path / "out.png").exists()


# ------------------------------------------------- --list-settings and argument order
def _without_banner(result):
    """stdout without the version line Blender 3.4 prints before any script runs."""
    return "".join(line for line in result.stdout.splitlines(keepends=True)
                   if not line.startswith("Blender 3.4"))


def test_list_settings_is_the_settings_model_on_both_entry_points(tmp_path):
    expected = "".join(line + "\n" for line in cli.settings_listing())
    on_pip_bpy = run_cli(["--list-settings"], cwd=tmp_path)
    assert on_pip_bpy.returncode == 0, on_pip_bpy.stderr
    assert on_pip_bpy.stdout == expected
    on_blender_34 = run_blender_cli(["--list-settings"], tmp_path)
    assert on_blender_34.returncode == 0, on_blender_34.stderr
    assert _without_banner(on_blender_34) == expected
    # What the issue saw: Blender's RNA paths for vectors, float32 noise, no enum values.
    assert "bpy.data" not in expected and "0.8999999" not in expected
    assert "manual_splits = 0.1, 0.3, 0.6 " in expected
    assert "one of UNIFORM, LOG, HYBRID, MANUAL" in expected


def test_a_lone_png_is_refused_the_same_way_on_both_entry_points(tmp_path):
    """Not read as a scene ("shot.png: file not found"): the message says the scene comes
    first, with the command each entry point is run with."""
    results = {"python -m csm_engine": run_cli(["shot.png"], cwd=tmp_path),
               "blender -b -P " + os.path.join(REPO, "csm_engine", "blender_cli.py") + " --":
                   run_blender_cli(["shot.png"], tmp_path)}
    for prog, result in results.items():
        assert result.returncode == 2, (prog, result.stderr)
        assert result.stderr.splitlines() == [
            f"csm: error: shot.png: that is the screenshot; the scene file comes first: "
            f"{prog} scene.json shot.png"], result.stderr
        assert _without_banner(result) == ""
    assert list(tmp_path.iterdir()) == []


def test_blender_binary_bridge_on_blender_34(tmp_path):
    shot = tmp_path / "shot.png"
    result = run_blender_cli([DEFAULT_SCENE, str(shot), "--resolution", "320x180"], tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    pixels = load_png(str(shot))
    assert pixels.shape == (180, 320, 4)
    assert_lit_landscape(pixels)
    bad = run_blender_cli(["nope.json"], tmp_path)
    assert bad.returncode == 3 and "nope.json" in bad.stderr


# ----------------------------------------------------------- the file the CLI writes
def _only_error(result):
    errors = [line for line in result.stderr.splitlines() if line.startswith("csm: error:")]
    assert len(errors) == 1 and "Traceback" not in result.stderr, result.stderr
    return errors[0]


def test_writes_exactly_the_named_png_and_nothing_else(tmp_path):
    shot = tmp_path / "Shot.PNG"                    # any case of .png is PNG
    result = run_cli([DEFAULT_SCENE, str(shot), "--resolution", "64x36"], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Shot.PNG"]
    assert load_png(str(shot)).shape == (36, 64, 4)
    umask = os.umask(0)
    os.umask(umask)
    assert shot.stat().st_mode & 0o777 == 0o666 & ~umask, oct(shot.stat().st_mode)


@pytest.mark.parametrize("name, words", [
    ("shot.jpg", ["shot.jpg", "PNG only"]),
    ("shot", ["shot", "PNG only"]),
    ("", ["empty"]),
    ("folder", ["folder", "is a folder"]),
    ("scene.json", ["scene.json"]),
])
def test_a_name_that_is_not_a_new_png_is_refused_before_rendering(tmp_path, name, words):
    (tmp_path / "folder").mkdir()
    (tmp_path / "shot.png").write_bytes(b"an unrelated file")
    scene = tmp_path / "scene.json"
    shutil.copy(DEFAULT_SCENE, scene)
    scene.write_text(scene.read_text().replace('"data/', '"' + os.path.join(
        os.path.dirname(os.path.dirname(DEFAULT_SCENE)), "")))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    result = run_cli([str(scene), name, "--resolution", "32x18"], cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    error = _only_error(result)
    for word in words:
        assert word in error, (word, error)
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    assert after == before, "nothing written, nothing replaced"
    assert not (tmp_path.parent / (tmp_path.name + ".png")).exists()


def test_a_leading_double_slash_is_the_root_not_the_blend_folder(tmp_path):
    shot = tmp_path / "x.png"
    result = run_cli([DEFAULT_SCENE, "/" + str(shot), "--resolution", "32x18"], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert shot.is_file()


def test_an_unwritable_folder_is_one_line_and_exit_5(tmp_path):
    result = run_cli([DEFAULT_SCENE, "/proc/csm_shot.png", "--resolution", "32x18"],
                     cwd=tmp_path)
    assert result.returncode == 5, result.stderr
    error = _only_error(result)
    assert "/proc/csm_shot.png" in error


def test_a_successful_run_prints_one_line_and_nothing_else(tmp_path):
    """No importer chatter, no EGL start-up complaints, no 'Fra: Mem' stats, no
    'Not freed memory blocks' at exit: the user's terminal shows only what concerns them."""
    shot = tmp_path / "quiet.png"
    result = run_cli([DEFAULT_SCENE, str(shot), "--resolution", "64x36"], cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert lines == [f"csm: wrote {shot} (64x36)"], lines


def test_the_blender_34_bridge_is_quiet_too(tmp_path):
    shot = tmp_path / "quiet.png"
    result = run_blender_cli([DEFAULT_SCENE, str(shot), "--resolution", "64x36"], tmp_path)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    # Blender prints its own version banner before any script runs.
    assert lines == ["Blender 3.4.1", f"csm: wrote {shot} (64x36)"], lines


def test_a_failed_render_is_one_line_exit_4_and_no_file(tmp_path):
    """A render that cannot run (here: a shader file saved in another encoding in a copy
    of the package) is one line naming the file, exit 4, and no PNG, old or new."""
    package = tmp_path / "pkg"
    shutil.copytree(os.path.join(REPO, "csm_engine"), package / "csm_engine",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(os.path.join(REPO, "shaders"), package / "shaders")
    lighting = package / "shaders" / "lighting_frag.glsl"
    lighting.write_bytes(lighting.read_bytes().replace(b"/*", b"/* \xff", 1))
    shot = tmp_path / "never.png"
    env = dict(os.environ, PYTHONPATH=str(package))
    result = subprocess.run([sys.executable, "-m", "csm_engine", DEFAULT_SCENE, str(shot),
                             "--resolution", "64x36"], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 4, result.stderr
    lines = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("csm: error: render failed:"), lines
    assert "lighting_frag.glsl:1: not UTF-8" in lines[0], lines
    assert not shot.exists()
