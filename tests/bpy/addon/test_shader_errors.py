"""A GLSL compile error names ``file.glsl:line`` of the line that is wrong (pip bpy 5.0).

The broken line is put into a copy of ``shaders/``, inside a function body, both in a
program's own file (lighting_frag.glsl) and in a file it includes (common.glsl), and the
message of ``ShaderLibrary.reload`` (what F5 reports) must name exactly that file and line.
Blender 3.4 and pip bpy 4.2 run the same check in tests/hosts/test_shader_errors_hosts.py.
"""
import re
import shutil

import bpy
import pytest

from tests.bpy.bpy_helpers import render_scene
from csm_engine.core import paths
from csm_engine.render import shaders

BROKEN = "  float broken = ;"


def break_shader(directory, name, broken=BROKEN):
    """Insert ``broken`` as the first line of the file's first function body; its line."""
    path = directory / name
    lines = path.read_text(encoding="utf-8").splitlines()
    line = lines.index("{") + 2          # 1-based number of the line after the first "{"
    lines.insert(line - 1, broken)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return line


@pytest.mark.parametrize("name, broken", [
    ("lighting_frag.glsl", BROKEN),                       # syntax error in the program's file
    ("common.glsl", BROKEN),                              # ... in an included file
    ("lighting_frag.glsl", "  float broken = nope;"),     # undeclared name (semantic error)
])
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
    path = directory / "common.glsl"
    path.write_bytes(path.read_bytes().replace(b"/*", b"/* caf\xe9 ", 1))
    library = shaders.ShaderLibrary(directory=str(directory))
    message = library.reload()
    assert message == "common.glsl:1: not UTF-8 text (byte 0xe9); save the file as UTF-8", \
        message
