"""The Shader Folder preference on every host and in every installed form.

Blender files add-on preferences under the add-on's module name: ``csm_engine`` for the
legacy zip (Blender 3.4) and for pip bpy calling ``register()``, but
``bl_ext.user_default.csm_engine`` for the extension (4.2+). Each host installs the add-on
as a user would (the packages come from tools/build.py, as in test_packaging.py), finds the
preference under that name, points it at a copy of the GLSL library with one edit in
lighting_frag.glsl (every lit pixel magenta), and F5 (Reload Shaders) must make the next
render magenta; a folder without the library is refused with one line and the edit keeps
rendering; clearing the preference brings back the add-on's own shaders and pixels. In
Blender 3.4 the preference is also saved and read back: the next session's first compile
reads the chosen folder.
"""

import os
import subprocess
import sys
import tomllib

import numpy as np
import pytest

pytestmark = pytest.mark.hosts

from tests.conftest import REPO

LIT_LINE = "  out_color = vec4(color, 1.0);"

# Runs inside the host. argv (after "--" for blender): form, archive or folder with the
# package, output folder. Prints one CSM_RESULT line.
HOST_SCRIPT = r'''
import importlib, json, math, os, shutil, sys
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
form, source, out_dir = argv[:3]
import bpy

result = {"blender": bpy.app.version_string, "form": form}
if form == "legacy":
    bpy.ops.preferences.addon_install(filepath=source)
    bpy.ops.preferences.addon_enable(module="csm_engine")
    module = "csm_engine"
elif form == "extension":
    bpy.ops.extensions.package_install_files(repo="user_default", filepath=source,
                                             enable_on_install=True)
    module = "bl_ext.user_default.csm_engine"
else:                              # pip bpy: the package on sys.path, register() by hand
    sys.path.insert(0, source)
    import csm_engine
    csm_engine.register()
    module = "csm_engine"
package = sys.modules[module]
result["package_file"] = package.__file__
preferences = importlib.import_module(module + ".blender.preferences")
shaders = importlib.import_module(module + ".render.shaders")
paths = importlib.import_module(module + ".core.paths")
result["bl_idname"] = preferences.CSM_AddonPreferences.bl_idname
result["addons"] = sorted(bpy.context.preferences.addons.keys())
addon = bpy.context.preferences.addons.get(module)
prefs = addon.preferences if addon is not None else None
result["prefs_type"] = type(prefs).__name__
result["prefs_found"] = preferences.addon_preferences() == prefs and prefs is not None
prop = prefs.bl_rna.properties["shader_folder"]
result["prop"] = [prop.name, prop.subtype, prop.default]
result["own_folder"] = paths.shaders_dir()

# Objects are removed by hand: reading factory settings would also reset the preferences
# and so disable the add-on just enabled.
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
scene = bpy.context.scene
scene.render.engine = "CSM"
scene.view_settings.view_transform = "Standard"
scene.render.resolution_x, scene.render.resolution_y = 64, 48
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "PNG"
scene.render.image_settings.color_mode = "RGB"
bpy.ops.mesh.primitive_plane_add(size=12)
bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1.2))
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.rotation_euler = (math.radians(35), math.radians(25), 0.0)
scene.collection.objects.link(sun)
camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
camera.location = (7.0, -7.0, 5.0)
camera.rotation_euler = (math.radians(63), 0.0, math.radians(45))
scene.collection.objects.link(camera)
scene.camera = camera


def render(name):
    scene.render.filepath = os.path.join(out_dir, name + ".png")
    bpy.ops.render.render(write_still=True)
    result[name] = scene.render.filepath


def reload_shaders():
    try:
        return sorted(bpy.ops.csm.reload_shaders())
    except RuntimeError as error:   # bpy.ops raises on an ERROR report
        return str(error).strip()


def step(name, folder):
    prefs.shader_folder = folder
    result[name + "_f5"] = reload_shaders()
    result[name + "_in_use"] = shaders.LIBRARY.folder_in_use
    render(name)


try:
    render("own")
    student = os.path.join(out_dir, "student", "shaders")
    shutil.copytree(paths.shaders_dir(), student)
    lighting = os.path.join(student, "lighting_frag.glsl")
    with open(lighting, encoding="utf-8") as handle:
        text = handle.read()
    result["edit_found"] = %(lit_line)r in text
    with open(lighting, "w", encoding="utf-8") as handle:
        handle.write(text.replace(%(lit_line)r, "  out_color = vec4(1.0, 0.0, 1.0, 1.0);"))
    result["student_folder"] = student
    step("student", student)
    result["empty_folder"] = os.path.join(out_dir, "empty")
    os.mkdir(result["empty_folder"])
    step("invalid", result["empty_folder"])
    step("cleared", "")
except Exception:
    import traceback
    result["error"] = traceback.format_exc()
print("CSM_RESULT " + json.dumps(result), flush=True)
if form == "register":     # pip bpy 4.2 segfaults at shutdown after a GPU-context render
    importlib.import_module(module + ".blender.compat").exit_process(0)
''' % {"lit_line": LIT_LINE}


@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    """(extension zip, legacy zip) built from this checkout by tools/build.py."""
    dist = str(tmp_path_factory.mktemp("dist"))
    built = subprocess.run([sys.executable, os.path.join(REPO, "tools", "build.py"), "--dist",
                            dist], capture_output=True, text=True, timeout=300,
                           stdin=subprocess.DEVNULL)
    assert built.returncode == 0, built.stdout + built.stderr
    with open(os.path.join(REPO, "blender_manifest.toml"), "rb") as handle:
        version = tomllib.load(handle)["version"]
    return (os.path.join(dist, f"csm_engine-{version}.zip"),
            os.path.join(dist, f"csm_engine-{version}-legacy.zip"))


def _magenta_share(hosts, png):
    rgb = hosts.read_png(png)[..., :3]
    return float(np.mean(np.all(np.abs(rgb - (1.0, 0.0, 1.0)) < 0.02, axis=-1)))


@pytest.mark.parametrize("host, form", [("blender 3.4", "legacy"), ("bpy 4.2", "extension"),
                                        ("bpy 4.2", "register"), ("bpy 5.0", "extension")])
def test_shader_folder_preference_on_every_host(hosts, host_dir, archives, host, form):
    if form == "register":
        source = os.path.join(str(host_dir), "work")
        hosts.copy_package(source)
    else:
        source = archives[0] if form == "extension" else archives[1]
    script = host_dir / "host_script.py"
    script.write_text(HOST_SCRIPT)
    out_dir = host_dir / "out"
    out_dir.mkdir()
    command = hosts.script_command(host, str(script), form, source, str(out_dir))
    run = hosts.run_host(command, hosts.user_dirs_env(str(host_dir)), str(host_dir))
    result = run.result
    assert run.returncode == 0 and result, run.describe()
    assert "error" not in result, f"{host}: {result['error']}\n{run.describe()}"
    module = "bl_ext.user_default.csm_engine" if form == "extension" else "csm_engine"
    assert result["bl_idname"] == module and module in result["addons"], result
    assert result["prefs_type"] == "CSM_AddonPreferences" and result["prefs_found"], result
    assert result["prop"] == ["Shader Folder", "DIR_PATH", ""], result
    if form != "register":     # what runs is the installed copy, in the throwaway folders
        assert result["own_folder"].startswith(str(host_dir / "blender-user")), result
    assert result["edit_found"], result
    assert _magenta_share(hosts, result["own"]) == 0.0
    # The student's edit shows after F5.
    assert result["student_f5"] == ["FINISHED"], result
    assert result["student_in_use"] == result["student_folder"], result
    assert _magenta_share(hosts, result["student"]) > 0.5, result
    # A folder without the library: one line naming it and what is missing; the edit runs on.
    message = result["invalid_f5"]
    assert message.startswith(f"Error: Shader Folder {result['empty_folder']}: missing "
                              "lighting_frag.glsl, "), message
    assert message.endswith("(keeping the previous shaders)") and "\n" not in message, message
    assert result["invalid_in_use"] == result["student_folder"], result
    np.testing.assert_array_equal(hosts.read_png(result["invalid"]),
                                  hosts.read_png(result["student"]))
    # Cleared: the add-on's own shaders and pixels again.
    assert result["cleared_f5"] == ["FINISHED"], result
    assert result["cleared_in_use"] == result["own_folder"], result
    np.testing.assert_array_equal(hosts.read_png(result["cleared"]),
                                  hosts.read_png(result["own"]))


# Runs inside `blender -b --factory-startup`. argv after "--": legacy zip, folder for the
# student's copy. Installs and enables the add-on, sets the Shader Folder to the edited
# copy and saves the preferences, as a user does once.
SAVE_PREFERENCE_SCRIPT = r'''
import json, os, shutil, sys
import bpy
zip_path, out_dir = sys.argv[sys.argv.index("--") + 1:][:2]
bpy.ops.preferences.addon_install(filepath=zip_path)
bpy.ops.preferences.addon_enable(module="csm_engine")
from csm_engine.core import paths
student = os.path.join(out_dir, "student", "shaders")
shutil.copytree(paths.shaders_dir(), student)
lighting = os.path.join(student, "lighting_frag.glsl")
with open(lighting, encoding="utf-8") as handle:
    text = handle.read()
with open(lighting, "w", encoding="utf-8") as handle:
    handle.write(text.replace(%(lit_line)r, "  out_color = vec4(1.0, 0.0, 1.0, 1.0);"))
bpy.context.preferences.addons["csm_engine"].preferences.shader_folder = student
result = {"edit_found": %(lit_line)r in text, "save": sorted(bpy.ops.wm.save_userpref())}
print("CSM_RESULT " + json.dumps(result), flush=True)
''' % {"lit_line": LIT_LINE}


def test_blender_3_4_keeps_the_preference_and_the_first_compile_reads_it(hosts, host_dir,
                                                                         archives):
    """Saved with the preferences, the Shader Folder is what the next session's first
    compile reads: a command-line render of the startup cube shows the edit."""
    blender = hosts.blender_binary()
    script = host_dir / "save_preference.py"
    script.write_text(SAVE_PREFERENCE_SCRIPT)
    env = hosts.user_dirs_env(str(host_dir))
    run = hosts.run_host([blender, "-b", "--factory-startup", "--python-exit-code", "1",
                          "--python", str(script), "--", archives[1], str(host_dir)],
                         env, str(host_dir))
    assert run.returncode == 0 and run.result == {"edit_found": True, "save": ["FINISHED"]}, \
        run.describe()
    # The startup file (cube, camera, light) with the saved preferences, rendered by CSM.
    run = hosts.run_host([blender, "-b", "-E", "CSM", "-o", str(host_dir / "render_####"),
                          "-F", "PNG", "-f", "1"], env, str(host_dir))
    png = host_dir / "render_0001.png"
    assert run.returncode == 0 and png.is_file(), run.describe()
    assert "Shader Folder" not in run.output, run.describe()     # no fallback to the own
    rgb = hosts.read_png(str(png))[..., :3]
    # Magenta through Blender's default view transform (Filmic): red and blue, no green.
    magenta = (rgb[..., 0] > 0.5) & (rgb[..., 2] > 0.5) & (rgb[..., 1] < 0.05)
    assert magenta.mean() > 0.1, magenta.mean()
