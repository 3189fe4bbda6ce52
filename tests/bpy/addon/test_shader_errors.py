"""A GLSL compile error names ``file.glsl:line`` of the line that is wrong (pip bpy 5.0).

The broken line is put into a copy of ``shaders/``, inside a function body, in a program's
own file (lighting_frag.glsl), in every file of the GLSL library that a program includes,
and after a conditional include (shadow_frag.glsl), and the message of
``ShaderLibrary.reload`` (what F5 reports) must name exactly that file and line. Blender 3.4
and pip bpy 4.2 run the same check in tests/hosts/test_shader_errors_hosts.py. F5 in a
checkout reads the top-level ``shaders/`` (the installed add-on's copy is checked in
tests/hosts/test_packaging.py), and a Shader Folder chosen in the add-on's preferences is
reported the same way (tests/bpy/addon/test_shader_folder.py has the rest of that path).
"""
import os
import re
import shutil

import bpy
import pytest

from tests.bpy.bpy_helpers import render_scene
from tests.conftest import REPO
from csm_engine.blender import preferences
from csm_engine.core import paths
from csm_engine.render import shaders

BROKEN = "  float broken = ;"
INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"', re.MULTILINE)


def included_files():
    """Every file of the GLSL library that some shader file includes."""
    names = set()
    for path in sorted(os.listdir(paths.shaders_dir())):
        if path.endswith(".glsl"):
            with open(os.path.join(paths.shaders_dir(), path), encoding="utf-8") as handle:
                names.update(INCLUDE.findall(handle.read()))
    return sorted(names)


def break_shader(directory, name, broken=BROKEN):
    """Insert ``broken`` as the first line of the file's first function body; its line."""
    path = directory / name
    lines = path.read_text(encoding="utf-8").splitlines()
    line = lines.index("{") + 2          # 1-based number of the line after the first "{"
    lines.insert(line - 1, broken)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return line


def test_the_library_has_the_files_the_lighting_pass_is_made_of():
    assert {"shadow_atlas.glsl", "shadow_pcf.glsl", "shadow_soft.glsl", "shadow_lookup.glsl",
            "cascade_selection.glsl", "brdf.glsl", "lights.glsl", "debug_views.glsl",
            "alpha_hash.glsl"} <= set(included_files())


@pytest.mark.parametrize("name, broken", [
    ("lighting_frag.glsl", BROKEN),                       # syntax error in the program's file
    ("lighting_frag.glsl", "  float broken = nope;"),     # undeclared name (semantic error)
    ("shadow_frag.glsl", BROKEN),                         # after an #ifdef'd #include
] + [(name, BROKEN) for name in included_files()])        # ... in every included file
def test_compile_error_names_file_and_line(empty_scene, tmp_path, name, broken):
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    empty_scene.collection.objects.link(camera)
    empty_scene.camera = camera
    render_scene(empty_scene, 16, 16)          # makes sure a GPU context exists
    directory = tmp_path / "shaders"
    shutil.copytree(paths.shaders_dir(), directory)
    line = break_shader(directory, name, broken)
    library = shaders.ShaderLibrary(directory=str(directory))
    message = library.reload()
    assert message and re.search(rf"(?<![\w.]){re.escape(name)}:{line}(?!\d)", message), \
        (line, message)
    assert library.last_error == message


def test_a_shader_file_that_is_not_utf8_is_a_clean_error(empty_scene, tmp_path):
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    empty_scene.collection.objects.link(camera)
    empty_scene.camera = camera
    render_scene(empty_scene, 16, 16)
    directory = tmp_path / "shaders"
    shutil.copytree(paths.shaders_dir(), directory)
    path = directory / "shadow_atlas.glsl"
    path.write_bytes(path.read_bytes().replace(b"/*", b"/* caf\xe9 ", 1))
    library = shaders.ShaderLibrary(directory=str(directory))
    message = library.reload()
    assert message == "shadow_atlas.glsl:1: not UTF-8 text (byte 0xe9); save the file as UTF-8", \
        message


def test_f5_in_a_checkout_reads_the_top_level_shaders_folder(empty_scene, tmp_path,
                                                             monkeypatch):
    """A checkout has no csm_engine/shaders/: the add-on reads (and F5 reloads) the
    repository's shaders/ beside the package. Shown on a copy of the checkout's layout, so
    the edit F5 must pick up is made in a copy, never in the checkout."""
    assert not os.path.exists(os.path.join(paths.PACKAGE_DIR, "shaders"))
    assert paths.shaders_dir() == os.path.join(REPO, "shaders")
    assert shaders.LIBRARY.folder == paths.shaders_dir()
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    empty_scene.collection.objects.link(camera)
    empty_scene.camera = camera
    render_scene(empty_scene, 16, 16)          # makes sure a GPU context exists
    checkout = tmp_path / "checkout"
    shutil.copytree(paths.shaders_dir(), checkout / "shaders")
    monkeypatch.setattr(paths, "CHECKOUT_DIR", str(checkout))
    library = shaders.ShaderLibrary()
    monkeypatch.setattr(shaders, "LIBRARY", library)
    assert library.folder == str(checkout / "shaders")
    line = break_shader(checkout / "shaders", "lighting_frag.glsl")
    with pytest.raises(RuntimeError) as failure:    # bpy.ops raises on an ERROR report
        bpy.ops.csm.reload_shaders()
    assert f"lighting_frag.glsl:{line}" in str(failure.value), str(failure.value)
    shutil.copy2(os.path.join(REPO, "shaders", "lighting_frag.glsl"),
                 checkout / "shaders" / "lighting_frag.glsl")
    generation = library.generation
    assert bpy.ops.csm.reload_shaders() == {'FINISHED'}
    assert library.last_error is None and library.generation == generation + 1


def test_f5_names_file_and_line_in_the_shader_folder_preference(empty_scene, tmp_path):
    """A student's own folder (the Shader Folder preference): F5 names the broken line
    there, keeps the previous shaders, and picks up the fix."""
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    empty_scene.collection.objects.link(camera)
    empty_scene.camera = camera
    render_scene(empty_scene, 16, 16)          # makes sure a GPU context exists
    folder = tmp_path / "student" / "shaders"
    shutil.copytree(paths.shaders_dir(), folder)
    prefs = preferences.addon_preferences(create=True)
    prefs.shader_folder = str(folder)
    try:
        line = break_shader(folder, "shadow_pcf.glsl")
        generation = shaders.LIBRARY.generation
        with pytest.raises(RuntimeError) as failure:    # bpy.ops raises on an ERROR report
            bpy.ops.csm.reload_shaders()
        assert f"shadow_pcf.glsl:{line}" in str(failure.value), str(failure.value)
        assert "keeping the previous shaders" in str(failure.value)
        assert shaders.LIBRARY.generation == generation
        shutil.copy2(os.path.join(paths.shaders_dir(), "shadow_pcf.glsl"), folder)
        assert bpy.ops.csm.reload_shaders() == {'FINISHED'}
        assert shaders.LIBRARY.folder_in_use == str(folder)
        assert shaders.LIBRARY.last_error is None
    finally:
        prefs.shader_folder = ""
        assert shaders.LIBRARY.reload() is None
    assert shaders.LIBRARY.folder_in_use == paths.shaders_dir()
