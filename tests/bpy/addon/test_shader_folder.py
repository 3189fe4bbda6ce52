"""The Shader Folder preference (pip bpy 5.0): a student points the add-on at the shaders/
of their checkout, and F5 (Reload Shaders) shows their edit.

The preference is set to a copy of the GLSL library in a temporary folder. Editing
lighting_frag.glsl there (every lit pixel one constant colour) and pressing F5 changes the
rendered pixels; a folder that lacks files is refused with one line naming the folder and
the files, and the last good shaders keep rendering; clearing the preference brings back the
add-on's own shaders. The panel names the folder in use and opens it in the system's file
browser. Blender 3.4 and pip bpy 4.2 run the same path in
tests/hosts/test_shader_folder_hosts.py.
"""
import os
import shutil
import stat

import bpy
import numpy as np
import pytest

from tests.bpy.bpy_helpers import RecordingLayout, cube_on_plane, render_scene
from csm_engine.blender import operators, preferences
from csm_engine.core import paths
from csm_engine.render import shaders

SIZE = (64, 48)
# What the edit turns every lit pixel into (linear RGB; the Standard view shows it as is).
MAGENTA = (1.0, 0.0, 1.0)
LIT_LINE = "  out_color = vec4(color, 1.0);"


def magenta_share(image):
    rgb = image[..., :3]
    return float(np.mean(np.all(np.abs(rgb - MAGENTA) < 0.02, axis=-1)))


def reload_shaders():
    """F5: {'FINISHED'}, or the message of the ERROR it reported."""
    try:
        return bpy.ops.csm.reload_shaders()
    except RuntimeError as error:       # bpy.ops raises on an ERROR report
        return str(error)


@pytest.fixture
def shader_folder(empty_scene):
    """Set the preference with ``shader_folder(path)``; afterwards it is cleared and the
    add-on's own shaders are compiled again, as the rest of the suite expects."""
    # Reading factory settings (empty_scene) drops pip bpy's entry for the add-on.
    prefs = preferences.addon_preferences(create=True)

    def choose(path):
        prefs.shader_folder = str(path)

    yield choose
    prefs.shader_folder = ""
    assert shaders.LIBRARY.reload() is None
    assert shaders.LIBRARY.folder_in_use == paths.shaders_dir()


@pytest.fixture
def lit_scene(empty_scene):
    cube_on_plane(empty_scene)
    return empty_scene


def test_the_preference_is_filed_under_the_addon_module_name():
    import csm_engine
    # "csm_engine" here; an extension's package is "bl_ext.<repository>.csm_engine".
    assert preferences.ADDON_MODULE == csm_engine.__name__ == "csm_engine"
    assert preferences.CSM_AddonPreferences.bl_idname == csm_engine.__name__
    prefs = preferences.addon_preferences(create=True)
    assert prefs == bpy.context.preferences.addons["csm_engine"].preferences
    prop = prefs.bl_rna.properties["shader_folder"]
    assert (prop.name, prop.subtype, prop.default) == ("Shader Folder", 'DIR_PATH', "")
    assert "Empty: the add-on's own shaders" in prop.description
    # Empty means the add-on's own, and the panel says so.
    assert preferences.chosen_shader_folder() == ""
    assert shaders.LIBRARY.folder == paths.shaders_dir()
    layout = RecordingLayout()
    preferences.draw_shader_folder(layout, bpy.context)
    assert layout.labels == ["Shaders: add-on's own"], layout.labels
    assert layout.operators == ["csm.open_shader_folder"]


def test_f5_reads_the_shader_folder_and_shows_the_edit(lit_scene, shader_folder, tmp_path):
    before = render_scene(lit_scene, *SIZE)["combined"]
    assert magenta_share(before) == 0.0
    checkout = tmp_path / "my checkout" / "shaders"
    shutil.copytree(paths.shaders_dir(), checkout)
    shader_folder(checkout)
    assert shaders.LIBRARY.folder == str(checkout)
    layout = RecordingLayout()
    preferences.draw_shader_folder(layout, bpy.context)   # not loaded yet: F5 loads it
    assert layout.labels == ["Shaders: add-on's own", "Shader Folder set: F5 loads it"]

    assert reload_shaders() == {'FINISHED'}
    assert shaders.LIBRARY.folder_in_use == str(checkout)
    layout = RecordingLayout()
    preferences.draw_shader_folder(layout, bpy.context)
    shown = paths.display_path(str(checkout), max_chars=preferences.SHOWN_PATH_CHARS)
    assert layout.labels == ["Shaders from:", shown], layout.labels
    assert shown.endswith(os.path.join("my checkout", "shaders")) and len(shown) <= 24
    copy = render_scene(lit_scene, *SIZE)["combined"]
    np.testing.assert_array_equal(copy, before)            # the same GLSL, the same pixels

    lighting = checkout / "lighting_frag.glsl"
    text = lighting.read_text(encoding="utf-8")
    assert LIT_LINE in text
    lighting.write_text(text.replace(LIT_LINE, "  out_color = vec4(1.0, 0.0, 1.0, 1.0);"),
                        encoding="utf-8")
    assert reload_shaders() == {'FINISHED'}
    edited = render_scene(lit_scene, *SIZE)["combined"]
    # The ground and the cube fill most of the frame; only the sky is left as it was.
    assert magenta_share(edited) > 0.5, magenta_share(edited)


def test_a_folder_without_the_library_is_one_line_and_the_last_shaders_keep_running(
        lit_scene, shader_folder, tmp_path):
    before = render_scene(lit_scene, *SIZE)["combined"]
    partial = tmp_path / "partial"
    shutil.copytree(paths.shaders_dir(), partial)
    (partial / "brdf.glsl").unlink()
    (partial / "shadow_pcf.glsl").unlink()
    empty = tmp_path / "empty"
    empty.mkdir()
    for folder, missing in ((partial, "missing brdf.glsl, shadow_pcf.glsl"),
                            (empty, "missing lighting_frag.glsl, "),
                            (tmp_path / "nowhere", "no such folder")):
        shader_folder(folder)
        message = reload_shaders()
        assert message.startswith(f"Error: Shader Folder {folder}: {missing}"), message
        line = message.strip()
        assert line.endswith(" (keeping the previous shaders)") and "\n" not in line, line
        assert shaders.LIBRARY.folder_in_use == paths.shaders_dir()
        still = render_scene(lit_scene, *SIZE)["combined"]
        np.testing.assert_array_equal(still, before)
    assert "more files" in shaders.folder_problem(str(empty))   # a long list is cut short
    layout = RecordingLayout()
    preferences.draw_shader_folder(layout, bpy.context)   # the error box shows why instead
    assert layout.labels == ["Shaders: add-on's own"], layout.labels


def test_clearing_the_preference_returns_to_the_addons_own_shaders(
        lit_scene, shader_folder, tmp_path):
    before = render_scene(lit_scene, *SIZE)["combined"]
    folder = tmp_path / "shaders"
    shutil.copytree(paths.shaders_dir(), folder)
    lighting = folder / "lighting_frag.glsl"
    lighting.write_text(lighting.read_text(encoding="utf-8").replace(
        LIT_LINE, "  out_color = vec4(1.0, 0.0, 1.0, 1.0);"), encoding="utf-8")
    shader_folder(folder)
    assert reload_shaders() == {'FINISHED'}
    assert magenta_share(render_scene(lit_scene, *SIZE)["combined"]) > 0.5
    shader_folder("")
    assert preferences.chosen_shader_folder() == ""
    assert shaders.LIBRARY.folder == paths.shaders_dir()
    assert reload_shaders() == {'FINISHED'}
    assert shaders.LIBRARY.folder_in_use == paths.shaders_dir()
    np.testing.assert_array_equal(render_scene(lit_scene, *SIZE)["combined"], before)


def test_the_first_compile_falls_back_to_the_addons_own_shaders(lit_scene, tmp_path):
    """With no shaders running yet, a Shader Folder that is incomplete or does not compile
    must not leave the engine without shaders: the add-on's own are used, and the error is
    kept for the panel."""
    render_scene(lit_scene, 16, 16)          # makes sure a GPU context exists
    broken = tmp_path / "broken"
    shutil.copytree(paths.shaders_dir(), broken)
    lighting = broken / "lighting_frag.glsl"
    lighting.write_text(lighting.read_text(encoding="utf-8").replace(
        LIT_LINE, "  out_color = vec4(color, 1.0) nope;"), encoding="utf-8")
    for folder, expected in ((tmp_path / "nowhere", f"Shader Folder {tmp_path / 'nowhere'}: "
                                                    "no such folder"),
                             (broken, "lighting_frag.glsl:")):
        library = shaders.ShaderLibrary(preferred_folder=lambda: str(folder))
        assert library.folder == str(folder)
        assert library.get("fxaa") is not None
        assert library.folder_in_use == paths.shaders_dir()
        assert expected in library.last_error and \
            library.last_error.endswith("(the add-on's own shaders are in use)"), library.last_error
        library.release()
    good = shaders.ShaderLibrary(preferred_folder=lambda: str(tmp_path / "good"))
    shutil.copytree(paths.shaders_dir(), tmp_path / "good")
    assert good.get("fxaa") is not None
    assert good.folder_in_use == str(tmp_path / "good") and good.last_error is None
    good.release()


def test_the_open_button_opens_the_folder_in_use(empty_scene, shader_folder, tmp_path,
                                                 monkeypatch):
    # Blender's wm.path_open hands the folder to xdg-open on Linux: a stand-in records it.
    record = tmp_path / "opened.txt"
    fake = tmp_path / "bin" / "xdg-open"
    fake.parent.mkdir()
    fake.write_text(f'#!/bin/sh\nprintf "%s\\n" "$1" >> "{record}"\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{fake.parent}{os.pathsep}{os.environ['PATH']}")
    assert bpy.ops.csm.open_shader_folder() == {'FINISHED'}
    assert record.read_text().splitlines() == [paths.shaders_dir()]
    description = operators.CSM_OT_open_shader_folder.description(bpy.context, None)
    assert paths.shaders_dir() in description


def test_a_long_folder_is_shortened_from_the_front():
    home = os.path.expanduser("~")
    assert paths.display_path(os.path.join(home, "csm", "shaders")) == \
        os.path.join("~", "csm", "shaders")
    long = os.path.join(os.sep, "srv", "courses", "cs562", "students", "someone", "project",
                        "shaders")
    shown = paths.display_path(long, max_chars=30)
    assert shown == "\u2026" + os.sep + os.path.join("someone", "project", "shaders"), shown
    assert len(shown) <= 30
    assert paths.display_path(os.path.join(os.sep, "a", "b")) == os.path.join(os.sep, "a", "b")
    # The last folder is kept whole however long it is.
    assert paths.display_path(os.sep + "x" * 40).endswith("x" * 40)
