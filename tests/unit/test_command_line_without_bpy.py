"""``python -m csm_engine`` on a Python that has no ``bpy``: one line saying how to run it
instead, and a non-zero exit, never a traceback. ``--help``, the argument checks and
``--list-settings`` (read from the settings model) answer without Blender.

Three Pythons without bpy: this interpreter with bpy refused by an import hook (as if pip
bpy were not installed), this interpreter without site-packages (no numpy either), and the
system's python3 when it has no bpy.
"""
import os
import re
import shlex
import shutil
import subprocess
import sys

import pytest

from csm_engine.blender import cli
from csm_engine.core import settings_model
from tests.conftest import REPO

# Runs ``python -m csm_engine`` with every import of bpy failing as a missing module does.
_WITHOUT_BPY = r"""
import importlib.abc, runpy, sys
class NoBpy(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "bpy":
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, NoBpy())
runpy.run_module("csm_engine", run_name="__main__", alter_sys=True)
"""


def _system_python():
    # Also when it is the Python running these tests (the unit tests run on Debian's
    # python3 too, see tests/hosts/test_core_without_blender.py).
    python = shutil.which("python3", path="/usr/bin:/usr/local/bin")
    if python is None:
        return None
    probe = subprocess.run([python, "-c", "import sys, numpy; sys.exit(sys.version_info < "
                            "(3, 8))"], capture_output=True)
    has_bpy = subprocess.run([python, "-c", "import bpy"], capture_output=True)
    return python if probe.returncode == 0 and has_bpy.returncode != 0 else None


PYTHONS = {
    "bpy refused": [sys.executable, "-c", _WITHOUT_BPY],
    "no site-packages": [sys.executable, "-S", "-m", "csm_engine"],
    "system python3": [_system_python(), "-m", "csm_engine"],
}


def run_without_bpy(args, cwd, python="bpy refused"):
    command = PYTHONS[python]
    if command[0] is None:
        pytest.skip("no system python3 with numpy and without bpy here")
    env = dict(os.environ, PYTHONPATH=REPO)
    return subprocess.run([*command, *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=60)


def only_error(result):
    """The one line a failed run prints, checked to be all it printed."""
    assert "Traceback" not in result.stderr, result.stderr
    assert result.stdout == "", result.stdout
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("csm: error: "), lines
    return lines[0]


# ------------------------------------------------------------------ no bpy: how to run it
@pytest.mark.parametrize("python", sorted(PYTHONS))
@pytest.mark.parametrize("where", ["checkout", "elsewhere"])
def test_without_bpy_one_line_names_three_ways_to_render(tmp_path, python, where):
    cwd = REPO if where == "checkout" else str(tmp_path)
    result = run_without_bpy(["scene.json", "shot.png"], cwd, python)
    assert result.returncode == cli.EXIT_NO_BLENDER != 0
    line = only_error(result)
    assert "has no bpy" in line, line
    # Each way repeats the user's arguments, with a path that works from where they are.
    dev, = re.findall(r"(\S+) render scene\.json shot\.png", line)
    assert os.path.isfile(os.path.join(cwd, dev)) and os.path.basename(dev) == "dev", line
    venv, = re.findall(r"(\S+) -m csm_engine scene\.json shot\.png", line)
    assert venv.endswith(os.path.join(".venv", "bin", "python")), line
    bridge, = re.findall(r"blender -b -P (\S+) -- scene\.json shot\.png", line)
    assert os.path.samefile(os.path.join(cwd, bridge),
                            os.path.join(REPO, "csm_engine", "blender_cli.py")), line
    if where == "checkout":
        assert (dev, bridge) == ("./dev", "csm_engine/blender_cli.py"), line
    assert not (tmp_path / "shot.png").exists()


def test_without_bpy_and_without_arguments_too(tmp_path):
    result = run_without_bpy([], tmp_path)
    assert result.returncode == cli.EXIT_NO_BLENDER
    line = only_error(result)
    assert re.search(r"\S+/dev render \(", line) and "blender_cli.py --" in line, line


def test_a_bpy_that_fails_to_import_is_named_with_its_reason(tmp_path):
    (tmp_path / "bpy.py").write_text("raise ImportError('libXi.so.6: cannot open shared "
                                     "object file')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), REPO]))
    result = subprocess.run([sys.executable, "-m", "csm_engine", "scene.json", "shot.png"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == cli.EXIT_NO_BLENDER
    line = only_error(result)
    assert "cannot import bpy (libXi.so.6: cannot open shared object file)" in line, line


def test_list_settings_on_a_python_without_numpy_is_one_line_too(tmp_path):
    result = run_without_bpy(["--list-settings"], tmp_path, "no site-packages")
    assert result.returncode == cli.EXIT_NO_BLENDER
    line = only_error(result)
    assert "has no numpy" in line and "blender_cli.py -- --list-settings" in line, line


def test_help_needs_no_blender(tmp_path):
    result = run_without_bpy(["--help"], tmp_path, "no site-packages")
    assert result.returncode == 0, result.stderr
    assert "--list-settings" in result.stdout and result.stderr == ""


# ------------------------------------------------------------- the screenshot comes second
@pytest.mark.parametrize("args, suggestion", [
    (["shot.png"], "scene.json shot.png"),
    (["Shot.PNG"], "scene.json Shot.PNG"),
    (["shot.png", "my scene.json"], "'my scene.json' shot.png"),
    (["shot.png", "--resolution", "64x36"], "scene.json shot.png"),
])
def test_a_png_where_the_scene_goes_is_refused_saying_the_scene_comes_first(
        tmp_path, args, suggestion):
    result = run_without_bpy(args, tmp_path)
    assert result.returncode == cli.EXIT_USAGE
    line = only_error(result)
    assert line == (f"csm: error: {args[0]}: that is the screenshot; the scene file comes "
                    f"first: python -m csm_engine {suggestion}"), line


# ------------------------------------------------------------------------ --list-settings
def _listing(result):
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    lines = result.stdout.splitlines()
    heads = {line.split(" = ")[0]: line for line in lines if not line.startswith(" ")}
    return lines, heads


@pytest.mark.parametrize("python", sorted(set(PYTHONS) - {"no site-packages"}))
def test_list_settings_without_blender_names_every_setting_once(tmp_path, python):
    lines, heads = _listing(run_without_bpy(["--list-settings"], tmp_path, python))
    assert list(heads) == [setting.identifier for setting in settings_model.SETTINGS]
    assert len(lines) == 2 * len(settings_model.SETTINGS)
    for head, setting in zip(heads.values(), settings_model.SETTINGS):
        allowed = head[head.index("[") + 1:-1]
        if setting.kind == settings_model.ENUM:
            assert allowed == "one of " + ", ".join(setting.identifiers), head
    text = "\n".join(lines)
    assert "bpy." not in text
    # No float32 noise such as 0.8999999761581421.
    assert not re.search(r"\d\.\d{6,}", text), text


def test_list_settings_values_units_and_allowed_values(tmp_path):
    lines, heads = _listing(run_without_bpy(["--list-settings"], tmp_path))
    expected = {
        "cascade_count": "cascade_count = 3 [1 to 4]",
        "fitted_split_lambda": "fitted_split_lambda = 0.9 [a fraction, 0 to 1]",
        "manual_splits": "manual_splits = 0.1, 0.3, 0.6 [0 to 1 each]",
        "resolution": "resolution = 2048 px [64 to 8192 px]",
        "blend_band": "blend_band = 2 m [0 m or more]",
        "occluder_margin": "occluder_margin = 100 m [0 m or more]",
        "fade_fraction": "fade_fraction = 0.1 [a fraction, 0 to 1]",
        "fit_to_visible": "fit_to_visible = on [on or off]",
        "split_scheme": "split_scheme = HYBRID [one of UNIFORM, LOG, HYBRID, MANUAL]",
    }
    for name, line in expected.items():
        assert " ".join(heads[name].split()) == line, heads[name]
    # The second line: the label the panel shows and what the setting does.
    index = lines.index(heads["split_lambda"])
    assert lines[index + 1] == ("    Lambda: Hybrid split weight over clip start .. shadow "
                                "distance (Fit to View off), 0 to 1: 0 = uniform, "
                                "1 = logarithmic.")


def test_list_settings_shows_set_overrides_and_refuses_bad_ones(tmp_path):
    lines, heads = _listing(run_without_bpy(
        ["--list-settings", "--set", "split_lambda=0.75", "--set", "debug_view=cascades",
         "--set", "manual_splits=0.2,0.4,0.7"], tmp_path))
    assert heads["split_lambda"].split()[:3] == ["split_lambda", "=", "0.75"]
    assert heads["debug_view"].split()[:3] == ["debug_view", "=", "CASCADES"]
    assert heads["manual_splits"].startswith("manual_splits = 0.2, 0.4, 0.7 ")
    result = run_without_bpy(["--list-settings", "--set", "pcf_radius=40"], tmp_path)
    assert result.returncode == cli.EXIT_USAGE
    assert "pcf_radius" in only_error(result)


# ------------------------------------------------------------------- formatting, in-process
@pytest.mark.parametrize("value, text", [
    (0.8999999761581421, "0.9"), (0.9, "0.9"), (100.0, "100"), (2.0, "2"), (0.0, "0"),
    (0.30000001192092896, "0.3"), (1e-05, "1e-05"), (-2.5, "-2.5"), (2048, "2048"),
])
def test_numbers_read_without_float_noise(value, text):
    assert cli.format_number(value, settings_model.BY_IDENTIFIER["split_lambda"]) == text


def test_every_setting_formats_from_the_model_alone():
    for setting in settings_model.SETTINGS:
        text = cli.format_value(setting.default, setting)
        assert text and "\n" not in text
        assert cli.allowed_values(setting)
        assert cli.first_sentence(setting.description).startswith(setting.description[:10])


def test_units_come_from_the_models_unit_and_subtype():
    by_id = settings_model.BY_IDENTIFIER
    assert cli.unit_symbol(by_id["blend_band"]) == "m"
    assert cli.unit_symbol(by_id["resolution"]) == "px"
    assert cli.unit_symbol(by_id["cascade_count"]) == ""
    angle = settings_model.Setting("angle", "Angle", settings_model.FLOAT, 0.5, "Light",
                                   "An angle", subtype="ANGLE", unit="ROTATION")
    assert cli.format_value(0.7853981852531433, angle) == "45 °"


def test_suggested_commands_quote_what_the_shell_would_split():
    message = cli.no_blender_message(ModuleNotFoundError("No module named 'bpy'", name="bpy"),
                                     ["my scene.json", "shot.png"], "python -m csm_engine")
    assert " render 'my scene.json' shot.png " in message, message
    assert shlex.split(message.split(" -- ")[-1]) == ["my scene.json", "shot.png"]


def test_list_settings_into_a_reader_that_stops_early_is_no_error(tmp_path):
    """``--list-settings | head``: the pipe closes before the listing is written."""
    env = dict(os.environ, PYTHONPATH=REPO)
    process = subprocess.Popen([*PYTHONS["bpy refused"], "--list-settings"], cwd=tmp_path,
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()          # the only reader goes before the child has started
    errors = process.stderr.read().decode()
    process.stderr.close()
    assert process.wait(timeout=60) == 0, errors
    assert errors == ""
