"""A GLSL compile error names ``file.glsl:line`` on every host, not only pip bpy 5.0.

Blender 3.4 and pip bpy 4.2 drop the location from their own compiler log, so there the
message comes from csm_engine/shader_diagnostics.py recompiling through raw GL. Each host
runs a script in a subprocess: a tiny RenderEngine with ``bl_use_gpu_context`` renders one
frame and, inside it, reloads a ShaderLibrary over a copy of ``shaders/`` with one broken
line (in lighting_frag.glsl, in an included file, after a conditional include). The package and the GLSL library are
copied from this checkout into the host's working folder (``shaders/`` beside
``csm_engine/``, as in the checkout), so no install is needed.
"""

import json
import re

import pytest

pytestmark = pytest.mark.hosts


# A program's own file, a file two includes deep (lighting_frag.glsl -> shadow_lookup.glsl
# -> shadow_soft.glsl), a semantic error, and a line after an #ifdef'd #include (whose
# skipped #line markers must not shift the numbers after #endif).
CASES = (("lighting_frag.glsl", "  float broken = ;"),
         ("shadow_soft.glsl", "  float broken = ;"),
         ("lighting_frag.glsl", "  float broken = nope;"),
         ("shadow_frag.glsl", "  float broken = ;"))

# Runs inside the host. argv (after "--" for blender): working folder. Prints CSM_RESULT.
HOST_SCRIPT = r'''
import json, os, shutil, sys
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
work = argv[0]
sys.path.insert(0, work)
import bpy
from csm_engine.render import shaders

CASES = json.loads(argv[1])
result = {"blender": bpy.app.version_string, "cases": []}


def break_shader(directory, name, broken):
    path = os.path.join(directory, name)
    with open(path, encoding="utf-8") as handle:
        lines = handle.read().splitlines()
    line = lines.index("{") + 2
    lines.insert(line - 1, broken)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")
    return line


class ErrorProbe(bpy.types.RenderEngine):
    bl_idname = "CSM_ERROR_PROBE"
    bl_label = "CSM error probe"
    bl_use_gpu_context = True

    def render(self, depsgraph):
        for index, (name, broken) in enumerate(CASES):
            directory = os.path.join(work, f"case{index}", "shaders")
            shutil.copytree(os.path.join(work, "shaders"), directory)
            line = break_shader(directory, name, broken)
            message = shaders.ShaderLibrary(directory=directory).reload()
            result["cases"].append({"file": name, "line": line, "message": message})
        good = shaders.ShaderLibrary(directory=os.path.join(work, "shaders"))
        result["good"] = good.reload()
        del good        # free the GPU shaders while their context is still current
        self.end_result(self.begin_result(0, 0, 4, 4))


bpy.utils.register_class(ErrorProbe)
scene = bpy.context.scene
scene.render.engine = "CSM_ERROR_PROBE"
scene.render.resolution_x = scene.render.resolution_y = 4
scene.render.resolution_percentage = 100
bpy.ops.render.render()
# pip bpy 4.2 segfaults at exit while a Python engine that used a GPU context is registered.
bpy.utils.unregister_class(ErrorProbe)
print("CSM_RESULT " + json.dumps(result), flush=True)
'''


@pytest.mark.parametrize("host", ["blender 3.4", "bpy 4.2", "bpy 5.0"])
def test_compile_error_names_file_and_line_on_every_host(hosts, host_dir, host):
    run = hosts.run_script_with_package(host, host_dir, HOST_SCRIPT, json.dumps(CASES))
    assert run.returncode == 0 and run.result, run.describe()
    assert run.result["good"] is None, run.result        # the real shaders still compile
    assert len(run.result["cases"]) == len(CASES), run.result
    for case in run.result["cases"]:
        name, line, message = case["file"], case["line"], case["message"]
        assert message and re.search(rf"(?<![\w.]){re.escape(name)}:{line}(?!\d)", message), \
            f"{run.result['blender']}: expected {name}:{line} in {message!r}"
