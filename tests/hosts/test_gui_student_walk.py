"""A student's path through the add-on in a real Blender 3.4 window (Xvfb, xdotool), in one
Blender: install the legacy zip from Preferences and enable it, import the default sample
scene from File > Import > CSM Sample Scene (Replace), Rendered shading, the CS562
assignment preset, Blend 2 -> 20 m, first person then Esc, the Shader Folder pointed at a
copy of the shaders, an edit in the copy and F5.

``gui_student_driver.py`` runs inside Blender and writes a screenshot and a JSON record per
step; this file starts the X server and Blender, then checks the records and the pixels.
``CSM_UPDATE_DOCS=1`` (``./dev gui-screenshots``) copies the screenshots, scaled down, to
``docs/images/walk_*.png``.
"""

import os
import shutil

import numpy as np
import pytest

from tests.conftest import REPO
from tests.hosts.gui_host import (  # the X server and Blender set-up
    fresh_blender, load_png, run_driver, save_for_docs, x_display)

pytestmark = [pytest.mark.gui, pytest.mark.slow]

DRIVER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "gui_student_driver.py")
DOCS_IMAGES = os.path.join(REPO, "docs", "images")
BLENDER_TIMEOUT_S = 200      # the driver gives up after 150 s
_ = x_display


@pytest.fixture(scope="module")
def walk(x_display, hosts, tmp_path_factory):
    blender, root, out_dir, env, legacy = fresh_blender(hosts, x_display, tmp_path_factory,
                                                       "gui_walk")
    # The student's copy of the shaders (as in their checkout), for the Shader Folder.
    shader_copy = root / "my_shaders"
    shutil.copytree(os.path.join(REPO, "shaders"), shader_copy)
    report, output, _ = run_driver(blender, DRIVER, [out_dir, legacy, shader_copy], env, root,
                                   "walk.json", BLENDER_TIMEOUT_S)
    if os.environ.get("CSM_UPDATE_DOCS") == "1":
        _update_docs(out_dir, report)
    return {"report": report, "steps": {s["name"]: s for s in report["steps"]},
            "dir": out_dir, "shader_copy": str(shader_copy), "env": env}


def _update_docs(out_dir, report):
    names = [s["screenshot"] for s in report["steps"]]
    names += [s[key] for s in report["steps"] for key in ("menu", "cascades", "flying") if key in s]
    for name in names:
        save_for_docs(out_dir / name, os.path.join(DOCS_IMAGES, name))


def viewport(walk, step, shot="screenshot"):
    """The viewport left of the sidebar, from one of a step's screenshots."""
    picture = load_png(str(walk["dir"] / step[shot]))
    rect = dict(step["viewport_region"])
    if step.get("sidebar_region"):
        rect["width"] = step["sidebar_region"]["x"] - rect["x"]
    top = picture.shape[0] - (rect["y"] + rect["height"])
    return picture[top:top + rect["height"], rect["x"]:rect["x"] + rect["width"], :3]


def test_installed_from_the_legacy_zip_and_enabled(walk):
    step = walk["steps"]["installed"]
    assert walk["report"]["blender"].startswith("3.4"), walk["report"]["blender"]
    # Install... copied it into the user's scripts folder, not the checkout.
    assert os.path.join(walk["env"]["BLENDER_USER_SCRIPTS"], "addons") in step["addon_file"]
    assert "csm" in step["addon_search"].lower()


def test_sample_scene_from_the_import_menu_replaces_the_startup_scene(walk):
    step = walk["steps"]["imported"]
    assert step["engine"] == 'CSM'
    assert [os.path.basename(s) for s in step["imported"]] == ["default.json"], step
    assert {"Cube", "Light", "Camera"} <= set(step["startup_objects"]), step
    # Replace: only the scene file's objects are left (its own camera and sun).
    assert step["objects_after"] == step["imported_objects"], step


def test_rendered_shading_shows_the_scene(walk):
    step = walk["steps"]["rendered"]
    assert (step["engine"], step["shading"]) == ('CSM', 'RENDERED')
    assert viewport(walk, step).std() > 0.05


def test_the_cs562_preset_makes_the_course_controls_act(walk):
    step = walk["steps"]["preset"]
    assert step["before"] == {"cascade_selection": 'MAP', "fit_to_visible": True}, step
    assert step["after"]["cascade_selection"] == 'DEPTH' and not step["after"]["fit_to_visible"]
    # The course's splits over the whole view move the cascades: some shadows change.
    # Measured: 1.1 % of the pixels change by more than 0.05 (the view is pixel-stable:
    # redraws without a change differ by 0.0).
    before = viewport(walk, walk["steps"]["rendered"])
    after = viewport(walk, step)
    assert (np.abs(after - before).max(axis=-1) > 0.05).mean() > 0.003


def test_blend_band_changes_the_picture(walk):
    step = walk["steps"]["blend"]
    assert (step["blend_before"], step["blend_after"]) == (2.0, 20.0), step
    assert step["debug_view"] == 'CASCADES'
    before = viewport(walk, step, "cascades")
    after = viewport(walk, step)
    changed = np.abs(after - before).max(axis=-1) > 0.05
    # A band ten times wider mixes neighbouring cascades' colours over a wide strip before
    # each split (green and blue mixed from 84 m on instead of 2 m before 181 m). Measured:
    # 5.1 % of the viewport changes by more than 0.05; the redraws without a change differ
    # by 0.0.
    assert changed.mean() > 0.02, changed.mean()


def test_first_person_then_esc_puts_the_camera_back(walk):
    step = walk["steps"]["first_person"]
    assert step["invoked"] == 1
    moved = np.linalg.norm(np.subtract(step["camera_flying"], step["camera_before"]))
    assert moved > 1.0, step["camera_flying"]
    np.testing.assert_allclose(step["camera_after_esc"], step["camera_before"], atol=1e-5)
    back = viewport(walk, step)
    flying = viewport(walk, step, "flying")
    before = viewport(walk, step, "lit")
    assert np.abs(flying - before).mean() > 0.02, np.abs(flying - before).mean()
    assert np.abs(back - before).mean() < 0.005, np.abs(back - before).mean()


def test_f5_reads_the_shader_folder_and_shows_an_edit(walk):
    folder, edit = walk["steps"]["shader_folder"], walk["steps"]["shader_edit"]
    assert folder["shader_error"] is None and edit["shader_error"] is None
    assert os.path.realpath(folder["folder_in_use"]) == os.path.realpath(walk["shader_copy"])
    before = viewport(walk, walk["steps"]["first_person"])
    same = viewport(walk, folder)
    tinted = viewport(walk, edit)
    # The copy, unedited, draws the same picture.
    assert np.abs(same - before).mean() < 0.005, np.abs(same - before).mean()
    # The edit multiplies the lit colour by (1, 0.45, 0.45) before the view transform; the
    # sky (drawn before that line) keeps its colour. On the green landscape, measured: red
    # unchanged, green 67 % and blue 60 % of before (0.45 in linear light, through sRGB).
    ground = (before[..., 1] > before[..., 2] + 0.05) & (before[..., 1] > before[..., 0])
    assert ground.mean() > 0.2, ground.mean()
    lit, now = before[ground].mean(axis=0), tinted[ground].mean(axis=0)
    assert abs(now[0] - lit[0]) < 0.02 * lit[0], (lit, now)
    assert (now[1:] < 0.8 * lit[1:]).all(), (lit, now)
    unchanged = np.abs(tinted - same).max(axis=-1) < 0.01
    # Measured: 38 % of the viewport (the sky) is unchanged.
    assert unchanged.mean() > 0.2, unchanged.mean()
