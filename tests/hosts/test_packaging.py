"""The packages from tools/build.py install and work the way a user would use them.

* Every package (extension zip, legacy zip, wheel) carries the whole ``csm_engine``
  package with its ``data/``, the repository's top-level GLSL library ``shaders/`` inside
  the package (as ``csm_engine/shaders/``), and LICENSE; none carries a measuring
  tool (benchmark, model fetching, ground truth, quality report) or starts processes.
* The extension zip passes Blender's own validator, then installs through
  ``extensions.package_install_files`` and enables in pip bpy 5.0 and pip bpy 4.2: CSM is
  then a render engine a scene can use, and it renders a lit cube from the installed copy;
  F5 (Reload Shaders) reloads the installed copy of the shaders.
* The legacy zip installs through ``preferences.addon_install`` + ``addon_enable`` in
  Debian's Blender 3.4, and ``blender -b file.blend -E CSM -f 1`` renders the default
  scene with the add-on enabled from the saved preferences.
* The wheel installs into a fresh virtual environment of pip bpy 5.0 and of pip bpy 4.2,
  and its ``csm-render`` command renders the default scene with lit and shadowed ground
  from another directory; ``pip install <checkout>`` installs the same files offline.

Each host runs in its own subprocess with throwaway Blender user folders and a working
directory outside the checkout, so what runs is the installed package. The packages are
built fresh into a temporary folder by the same command as ``./dev build``.
"""

import ast
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

import numpy as np
import pytest

pytestmark = pytest.mark.hosts

from tests.conftest import PACKAGE, REPO
SHADERS = os.path.join(REPO, "shaders")
RENDER_SIZE = (160, 120)
# A pixel counts as lit when the sun adds at least this much to its luminance (0..1 PNG).
LIT_THRESHOLD = 0.05
# The smallest share of the frame that must be lit by the sun: a cube or a landscape
# in view covers far more; an engine that draws nothing covers none.
MIN_LIT_FRACTION = 0.01
# Modules of tools/csm_tools: measuring tools that must never reach a user's install.
MEASURING_TOOLS = {"bench", "bench_models", "bench_scenes", "ground_truth", "quality_report",
                   "report_io", "csm_tools"}
# Ways to start another process; the add-on never does (the manifest asks for files only).
PROCESS_CALLS = {("os", "system"), ("os", "popen"), ("os", "execv"), ("os", "execvp"),
                 ("os", "spawnv"), ("os", "posix_spawn"), ("os", "fork")}


def _manifest():
    with open(os.path.join(REPO, "blender_manifest.toml"), "rb") as handle:
        return tomllib.load(handle)


def _run_build(repo_root, dist_dir):
    return subprocess.run([sys.executable, os.path.join(repo_root, "tools", "build.py"),
                           "--dist", dist_dir], capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL)


def _package_paths(dist_dir, version):
    return (os.path.join(dist_dir, f"csm_engine-{version}.zip"),
            os.path.join(dist_dir, f"csm_engine-{version}-legacy.zip"),
            os.path.join(dist_dir, f"csm_engine-{version}-py3-none-any.whl"))


@pytest.fixture(scope="session")
def archives(tmp_path_factory):
    """(extension zip, legacy zip, wheel) built from this checkout by tools/build.py."""
    dist_dir = str(tmp_path_factory.mktemp("dist"))
    result = _run_build(REPO, dist_dir)
    assert result.returncode == 0, f"tools/build.py failed:\n{result.stdout}{result.stderr}"
    paths = _package_paths(dist_dir, _manifest()["version"])
    for path in paths:
        assert os.path.isfile(path), f"tools/build.py did not write {path}"
        assert path in result.stdout, f"tools/build.py did not print {path}:\n{result.stdout}"
    return paths


def _files_under(top, inside=""):
    files = set()
    for folder, dirs, names in os.walk(top):
        dirs[:] = [d for d in dirs if d != "__pycache__" and not d.startswith(".")]
        for name in names:
            if not name.startswith(".") and not name.endswith((".pyc", "~")):
                relative = os.path.relpath(os.path.join(folder, name), top).replace(os.sep, "/")
                files.add(inside + relative)
    return files


def _shader_files():
    """The checkout's GLSL library as every package carries it: inside the package."""
    files = _files_under(SHADERS, "shaders/")
    assert "shaders/lighting_frag.glsl" in files and len(files) >= 10, sorted(files)
    return files


def _source_files():
    """What every package must carry, relative to the package folder: all of csm_engine
    (code, data/), the top-level shaders/ as the package's shaders/, and LICENSE."""
    assert not os.path.exists(os.path.join(PACKAGE, "shaders")), (
        "the GLSL lives in the top-level shaders/, not in csm_engine/shaders/")
    return {"LICENSE"} | _files_under(PACKAGE) | _shader_files()


def _bl_info():
    with open(os.path.join(PACKAGE, "__init__.py"), encoding="utf-8") as handle:
        tree = ast.parse(handle.read())
    return next(ast.literal_eval(node.value) for node in tree.body
                if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "bl_info")


def _wheel_info_dir(wheel):
    return os.path.basename(wheel).split("-py3-")[0] + ".dist-info"


# --- the packages themselves -------------------------------------------------------------

def test_extension_zip_has_the_package_at_its_root_with_shaders_and_data(archives):
    names = set(zipfile.ZipFile(archives[0]).namelist())
    missing = _source_files() - names
    assert not missing, f"extension zip lacks {sorted(missing)}"
    assert "blender_manifest.toml" in names
    assert "scenes/default.json" not in names and "data/scenes/default.json" in names
    assert _shader_files() <= names and "core/paths.py" in names
    stray = [n for n in names if "__pycache__" in n or n.endswith(".pyc") or n.startswith("tests/")]
    assert not stray, f"extension zip carries build droppings: {stray}"


def test_legacy_zip_is_one_csm_engine_folder_with_shaders_and_data(archives):
    names = set(zipfile.ZipFile(archives[1]).namelist())
    expected = {"csm_engine/" + name for name in _source_files()}
    missing = expected - names
    assert not missing, f"legacy zip lacks {sorted(missing)}"
    assert {"csm_engine/" + name for name in _shader_files()} <= names
    outside = [n for n in names if not n.startswith("csm_engine/")]
    assert not outside, f"legacy zip has files outside csm_engine/: {outside}"
    stray = [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
    assert not stray, f"legacy zip carries build droppings: {stray}"


def test_wheel_has_the_package_with_shaders_data_and_a_csm_render_command(archives):
    wheel = archives[2]
    info = _wheel_info_dir(wheel)
    with zipfile.ZipFile(wheel) as bundle:
        names = set(bundle.namelist())
        expected = {"csm_engine/" + n for n in _source_files() if n != "LICENSE"}
        missing = expected - names
        assert not missing, f"wheel lacks {sorted(missing)}"
        assert {"csm_engine/" + name for name in _shader_files()} <= names
        outside = [n for n in names if not n.startswith(("csm_engine/", info + "/"))]
        assert not outside, f"wheel has files outside csm_engine/ and {info}/: {outside}"
        assert {f"{info}/{n}" for n in ("METADATA", "WHEEL", "RECORD", "entry_points.txt",
                                        "LICENSE")} <= names, sorted(names)
        wheel_file = bundle.read(f"{info}/WHEEL").decode()
        assert "Root-Is-Purelib: true" in wheel_file and "Tag: py3-none-any" in wheel_file
        entry_points = bundle.read(f"{info}/entry_points.txt").decode()
        assert "[console_scripts]" in entry_points and "csm-render = csm_engine." in entry_points
        metadata = bundle.read(f"{info}/METADATA").decode()
        # Users bring their own bpy: the wheel must never pull one in.
        requires = [line for line in metadata.splitlines() if line.startswith("Requires-Dist:")]
        assert not [r for r in requires if "bpy" in r.lower()], requires
        # The farm's Dask comes only with the extra: pip install csm_engine[farm].
        assert "Provides-Extra: farm" in metadata.splitlines()
        assert [r for r in requires if r.endswith('; extra == "farm"')] == \
            ['Requires-Dist: distributed>=2024.1; extra == "farm"'], requires
        # RECORD lists every other file with its size and hash, as pip checks on install.
        record = {line.split(",")[0] for line in bundle.read(f"{info}/RECORD").decode().splitlines()}
        assert record == names, sorted(record ^ names)
    stray = [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
    assert not stray, f"wheel carries build droppings: {stray}"


def test_every_package_carries_the_gpl_text(archives):
    with open(os.path.join(REPO, "LICENSE"), "rb") as handle:
        license_text = handle.read()
    assert b"GNU GENERAL PUBLIC LICENSE" in license_text and b"Version 3" in license_text
    assert b"END OF TERMS AND CONDITIONS" in license_text, "LICENSE is not the full GPL-3 text"
    where = {archives[0]: "LICENSE", archives[1]: "csm_engine/LICENSE",
             archives[2]: _wheel_info_dir(archives[2]) + "/LICENSE"}
    for archive, name in where.items():
        with zipfile.ZipFile(archive) as bundle:
            assert bundle.read(name) == license_text, f"{archive}: {name} is not LICENSE"


def _process_uses(tree):
    """Every import of subprocess, mention of it by name, and os.system-style call."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.split(".")[0] == "subprocess"]
        elif isinstance(node, ast.ImportFrom):
            if (node.module or "").split(".")[0] == "subprocess":
                found.append(f"from {node.module} import ...")
            elif node.module == "os":
                found += [f"from os import {a.name}" for a in node.names
                          if ("os", a.name) in PROCESS_CALLS]
        elif isinstance(node, ast.Name) and node.id == "subprocess":
            found.append("subprocess")
        elif isinstance(node, ast.Constant) and node.value == "subprocess":
            found.append("'subprocess'")
        elif (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
              and (node.value.id, node.attr) in PROCESS_CALLS):
            found.append(f"{node.value.id}.{node.attr}")
    return found


def _imported_modules(tree):
    modules = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            modules.update(part for a in node.names for part in a.name.split("."))
        elif isinstance(node, ast.ImportFrom):
            modules.update((node.module or "").split("."))
            modules.update(a.name for a in node.names)
    return modules


def test_no_package_carries_measuring_tools_or_starts_processes(archives):
    checked = 0
    for archive in archives:
        with zipfile.ZipFile(archive) as bundle:
            for name in bundle.namelist():
                parts = name.split("/")
                stems = {os.path.splitext(part)[0] for part in parts}
                tools = stems & MEASURING_TOOLS
                assert not tools, f"{archive} ships the measuring tool {name}"
                if not name.endswith(".py"):
                    continue
                source = bundle.read(name).decode("utf-8")
                tree = ast.parse(source, name)
                uses = _process_uses(tree)
                assert not uses, f"{archive}: {name} starts processes: {uses}"
                imports = _imported_modules(tree) & MEASURING_TOOLS
                assert not imports, f"{archive}: {name} imports measuring tools {imports}"
                checked += 1
    assert checked >= 3 * 20, f"only {checked} Python files found in the packages"


def test_one_version_in_manifest_bl_info_pyproject_and_wheel(archives):
    version = _manifest()["version"]
    with open(os.path.join(REPO, "pyproject.toml"), "rb") as handle:
        project = tomllib.load(handle)["project"]
    # pyproject.toml names no version of its own: tools/build.py takes the manifest's.
    assert "version" not in project and project["dynamic"] == ["version"], project
    assert ".".join(map(str, _bl_info()["version"])) == version
    wheel = archives[2]
    assert os.path.basename(wheel) == f"csm_engine-{version}-py3-none-any.whl"
    with zipfile.ZipFile(wheel) as bundle:
        metadata = bundle.read(_wheel_info_dir(wheel) + "/METADATA").decode()
    assert f"\nVersion: {version}\n" in metadata, metadata[:300]


def test_manifest_and_bl_info_agree(archives):
    manifest = _manifest()
    with zipfile.ZipFile(archives[0]) as bundle:
        built = tomllib.loads(bundle.read("blender_manifest.toml").decode())
    assert built == manifest
    assert manifest["id"] == "csm_engine" and manifest["type"] == "add-on"
    assert manifest["blender_version_min"] == "4.2.0"
    assert manifest["license"] == ["SPDX:GPL-3.0-or-later"]
    # The file permission only: a scene file is data and never needs network or more.
    assert set(manifest["permissions"]) == {"files"}
    bl_info = _bl_info()
    assert ".".join(map(str, bl_info["version"])) == manifest["version"]
    assert tuple(bl_info["blender"]) <= (3, 4, 0)


def test_extension_zip_passes_blenders_validator(archives, hosts):
    tool = hosts.extension_tool()
    tags = os.path.join(tool.split(os.sep + "scripts" + os.sep)[0], "scripts", "modules",
                        "_bpy_internal", "extensions", "tags.py")
    result = subprocess.run([sys.executable, tool, "validate", archives[0], "--valid-tags", tags],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f"validator rejected {archives[0]}:\n{result.stdout}{result.stderr}"
    assert "Success" in result.stdout, result.stdout


def _copy_checkout(target):
    """The parts of the checkout that tools/build.py reads, in a folder of another name."""
    for name in ("tools", "csm_engine", "shaders"):
        shutil.copytree(os.path.join(REPO, name), os.path.join(target, name),
                        ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("blender_manifest.toml", "LICENSE", "pyproject.toml", "README.md"):
        shutil.copy2(os.path.join(REPO, name), target)


def test_build_works_from_any_folder_name_and_gives_the_same_archives(archives, tmp_path):
    clone = tmp_path / "some other clone name"
    _copy_checkout(str(clone))
    result = _run_build(str(clone), str(clone / "dist"))
    assert result.returncode == 0, result.stdout + result.stderr
    for original in archives:
        copy = clone / "dist" / os.path.basename(original)
        with zipfile.ZipFile(original) as a, zipfile.ZipFile(copy) as b:
            assert sorted(a.namelist()) == sorted(b.namelist())
            for name in a.namelist():
                assert a.read(name) == b.read(name), f"{name} differs between builds"


def test_build_refuses_a_manifest_blender_would_reject_with_one_clear_line(tmp_path):
    clone = tmp_path / "broken"
    _copy_checkout(str(clone))
    manifest = (clone / "blender_manifest.toml").read_text()
    # Blender requires the tagline to end without punctuation.
    broken = manifest.replace(f'tagline = "{_manifest()["tagline"]}"',
                              f'tagline = "{_manifest()["tagline"]}."')
    assert broken != manifest
    (clone / "blender_manifest.toml").write_text(broken)
    result = _run_build(str(clone), str(clone / "dist"))
    assert result.returncode == 1
    assert "tagline" in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert not (clone / "dist" / "csm_engine-0.1.0-legacy.zip").exists()


def test_build_refuses_to_ship_without_the_license_or_with_two_versions(tmp_path):
    clone = tmp_path / "no license"
    _copy_checkout(str(clone))
    (clone / "LICENSE").unlink()
    result = _run_build(str(clone), str(clone / "dist"))
    assert result.returncode == 1
    assert "LICENSE is missing" in result.stderr and "Traceback" not in result.stderr, result.stderr
    assert not any(os.path.isfile(p) for p in _package_paths(str(clone / "dist"), "0.1.0"))

    shutil.copy2(os.path.join(REPO, "LICENSE"), clone / "LICENSE")
    init = clone / "csm_engine" / "__init__.py"
    init.write_text(init.read_text().replace('"version": (', '"version": (9, ', 1))
    result = _run_build(str(clone), str(clone / "dist"))
    assert result.returncode == 1
    assert "version mismatch" in result.stderr and "Traceback" not in result.stderr, result.stderr


def test_build_ships_the_top_level_shaders_and_refuses_a_second_or_missing_copy(tmp_path):
    clone = tmp_path / "two copies"
    _copy_checkout(str(clone))
    shutil.copytree(clone / "shaders", clone / "csm_engine" / "shaders")
    result = _run_build(str(clone), str(clone / "dist"))
    assert result.returncode == 1
    assert "csm_engine/shaders exists" in result.stderr and "Traceback" not in result.stderr, \
        result.stderr
    shutil.rmtree(clone / "csm_engine" / "shaders")
    shutil.rmtree(clone / "shaders")
    result = _run_build(str(clone), str(clone / "dist"))
    assert result.returncode == 1
    assert "shaders/lighting_frag.glsl is missing" in result.stderr, result.stderr
    assert not any(os.path.isfile(p) for p in _package_paths(str(clone / "dist"), "0.1.0"))


def test_the_sdist_keeps_the_checkout_layout_and_builds_the_same_wheel(archives, tmp_path):
    """pip builds from an sdist too: it has shaders/ at the top as the checkout does, and
    the backend inside it makes the very wheel tools/build.py makes."""
    import tarfile
    command = [sys.executable, "-c", "import sys, build; print(build.build_sdist(sys.argv[1]))",
               str(tmp_path)]
    made = subprocess.run(command, cwd=os.path.join(REPO, "tools"), capture_output=True,
                          text=True, timeout=300)
    assert made.returncode == 0, made.stderr
    with tarfile.open(tmp_path / made.stdout.strip()) as archive:
        archive.extractall(tmp_path / "sdist", filter="data")
    (root,) = (tmp_path / "sdist").iterdir()
    assert {"shaders/" + n.split("/", 1)[1] for n in _shader_files()} == {
        f"shaders/{p.name}" for p in (root / "shaders").iterdir()}
    assert not (root / "csm_engine" / "shaders").exists()
    command = [sys.executable, "-c", "import sys, build; print(build.build_wheel(sys.argv[1]))",
               str(tmp_path / "wheel")]
    made = subprocess.run(command, cwd=str(root / "tools"), capture_output=True, text=True,
                          timeout=300)
    assert made.returncode == 0, made.stderr
    with zipfile.ZipFile(archives[2]) as a, \
            zipfile.ZipFile(tmp_path / "wheel" / made.stdout.strip()) as b:
        assert sorted(a.namelist()) == sorted(b.namelist())
        for name in a.namelist():
            assert a.read(name) == b.read(name), f"{name} differs between the wheels"


# --- pip bpy hosts: install the extension and render with it -----------------------------

# Runs inside the host. argv: extension zip, output PNG folder. Prints one CSM_RESULT line.
EXTENSION_HOST_SCRIPT = r'''
import json, math, os, sys
import bpy

zip_path, out_dir = sys.argv[1], sys.argv[2]
result = {"blender": bpy.app.version_string}
try:
    result["install"] = sorted(bpy.ops.extensions.package_install_files(
        repo="user_default", filepath=zip_path, enable_on_install=True))
except Exception as error:  # reported to the test, which fails with the message
    result["install_error"] = str(error)
result["addons"] = sorted(bpy.context.preferences.addons.keys())
result["engines"] = {
    getattr(cls, "bl_idname", ""): {"module": cls.__module__, "label": getattr(cls, "bl_label", ""),
                                     "use_gpu_context": getattr(cls, "bl_use_gpu_context", None)}
    for cls in bpy.types.RenderEngine.__subclasses__()}
package = sys.modules.get("bl_ext.user_default.csm_engine")
result["package_file"] = getattr(package, "__file__", None)
if package is not None:
    import importlib
    paths = importlib.import_module(package.__name__ + ".core.paths")
    result["shaders_dir"] = paths.shaders_dir()
    result["default_scene"] = paths.default_scene_path()

def make_scene(with_sun):
    # Objects are removed by hand: reading factory settings would also reset the
    # preferences and so disable the extension just installed.
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene = bpy.context.scene
    scene.render.engine = "CSM"
    scene.world = bpy.data.worlds.new("Black")
    scene.world.color = (0.0, 0.0, 0.0)
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_x, scene.render.resolution_y = %(width)d, %(height)d
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location = (5.0, -5.0, 4.0)
    camera.rotation_euler = (math.radians(60), 0.0, math.radians(45))
    scene.collection.objects.link(camera)
    scene.camera = camera
    if with_sun:
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy = 3.0
        sun.rotation_euler = (math.radians(40), math.radians(20), math.radians(30))
        scene.collection.objects.link(sun)
    return scene

try:
    scene = make_scene(with_sun=True)
    result["scene_engine"] = scene.render.engine
    for name, with_sun in (("lit", True), ("unlit", False)):
        scene = make_scene(with_sun)
        scene.render.filepath = os.path.join(out_dir, name + ".png")
        bpy.ops.render.render(write_still=True)
        result[name + "_png"] = scene.render.filepath
except Exception as error:
    result["render_error"] = "%%s: %%s" %% (type(error).__name__, error)

# F5 in the installed add-on: it reloads the installed copy of the shaders. A broken line
# there is reported with its file and line, and the fix picked up by the next F5.
def reload_shaders():
    try:
        return sorted(bpy.ops.csm.reload_shaders())
    except RuntimeError as error:   # bpy.ops raises on an ERROR report
        return str(error)

try:
    if package is not None:
        library = importlib.import_module(package.__name__ + ".render.shaders").LIBRARY
        result["f5_folder"] = library.folder
        result["f5"] = reload_shaders()
        lighting = os.path.join(library.folder, "lighting_frag.glsl")
        with open(lighting, encoding="utf-8") as handle:
            good = handle.read()
        lines = good.splitlines()
        result["f5_broken_line"] = lines.index("{") + 2
        lines.insert(result["f5_broken_line"] - 1, "  float broken = ;")
        with open(lighting, "w", encoding="utf-8") as handle:
            handle.write("\n".join(lines) + "\n")
        result["f5_broken"] = reload_shaders()
        with open(lighting, "w", encoding="utf-8") as handle:
            handle.write(good)
        result["f5_fixed"] = reload_shaders()
except Exception as error:
    result["f5_error"] = "%%s: %%s" %% (type(error).__name__, error)
print("CSM_RESULT " + json.dumps(result), flush=True)
''' % {"width": RENDER_SIZE[0], "height": RENDER_SIZE[1]}


def _assert_sun_lights_the_frame(lit_png, unlit_png, hosts, what):
    lit, unlit = hosts.read_png(lit_png), hosts.read_png(unlit_png)
    assert lit.shape[:2] == (RENDER_SIZE[1], RENDER_SIZE[0]), f"{what}: {lit_png} is {lit.shape}"
    gain = hosts.luminance(lit) - hosts.luminance(unlit)
    lit_fraction = float(np.mean(gain > LIT_THRESHOLD))
    assert lit_fraction >= MIN_LIT_FRACTION, (
        f"{what}: the sun lights only {lit_fraction:.2%} of the frame (max gain "
        f"{gain.max():.3f}); expected a lit object in view")


def _install_extension_and_render(python, archives, host_dir, hosts, what):
    script = host_dir / "host_script.py"
    script.write_text(EXTENSION_HOST_SCRIPT)
    out_dir = host_dir / "renders"
    out_dir.mkdir()
    env = hosts.user_dirs_env(str(host_dir))
    run = hosts.run_host([python, str(script), archives[0], str(out_dir)], env, str(host_dir))
    result = run.result
    assert run.returncode == 0 and result, f"{what} host failed\n{run.describe()}"
    assert "install_error" not in result, f"{what}: install failed: {result['install_error']}\n{run.describe()}"
    assert result["install"] == ["FINISHED"], result
    assert "bl_ext.user_default.csm_engine" in result["addons"], result["addons"]
    engine = result["engines"].get("CSM")
    assert engine, f"{what}: no CSM render engine after install; engines: {result['engines']}"
    assert engine["label"] == "CSM" and engine["use_gpu_context"] is True, engine
    assert engine["module"].startswith("bl_ext.user_default.csm_engine"), engine
    # The code, shaders and scenes that run are the installed ones, in the throwaway folders.
    user_root = str(host_dir / "blender-user")
    for key in ("package_file", "shaders_dir", "default_scene"):
        assert result.get(key, "").startswith(user_root), f"{what}: {key} = {result.get(key)}"
    assert os.path.isfile(result["default_scene"])
    assert "render_error" not in result, f"{what}: render failed: {result['render_error']}\n{run.describe()}"
    assert result["scene_engine"] == "CSM"
    _assert_sun_lights_the_frame(result["lit_png"], result["unlit_png"], hosts, what)
    # F5 reloads the installed copy: it reports a line broken there, then picks up the fix.
    assert "f5_error" not in result, f"{what}: F5 failed: {result['f5_error']}\n{run.describe()}"
    assert result["f5_folder"] == result["shaders_dir"], result
    assert result["f5"] == ["FINISHED"], result
    assert f"lighting_frag.glsl:{result['f5_broken_line']}" in result["f5_broken"], result
    assert "keeping the previous shaders" in result["f5_broken"], result
    assert result["f5_fixed"] == ["FINISHED"], result
    return result


def test_extension_installs_enables_and_renders_in_pip_bpy_5_0(archives, host_dir, hosts):
    result = _install_extension_and_render(hosts.bpy50_python(), archives, host_dir, hosts,
                                           "pip bpy 5.0")
    assert result["blender"].startswith("5.0"), result["blender"]


def test_extension_installs_enables_and_renders_in_pip_bpy_4_2(archives, host_dir, hosts):
    result = _install_extension_and_render(hosts.bpy42_python(), archives, host_dir, hosts,
                                           "pip bpy 4.2")
    assert result["blender"].startswith("4.2"), result["blender"]


# --- Debian Blender 3.4: legacy zip, saved preferences, command-line render ---------------

# Runs inside `blender -b --factory-startup --python`. argv after "--": legacy zip, folder for
# the .blend files. Installs and enables like Preferences > Add-ons > Install, saves the
# preferences, then saves the default scene with and without its sun.
LEGACY_HOST_SCRIPT = r'''
import json, os, sys
import bpy

zip_path, out_dir = sys.argv[sys.argv.index("--") + 1:][:2]
result = {"blender": bpy.app.version_string}
result["install"] = sorted(bpy.ops.preferences.addon_install(filepath=zip_path))
result["enable"] = sorted(bpy.ops.preferences.addon_enable(module="csm_engine"))
result["addons"] = sorted(bpy.context.preferences.addons.keys())
package = sys.modules.get("csm_engine")
result["package_file"] = getattr(package, "__file__", None)
result["engines"] = {getattr(cls, "bl_idname", ""): cls.__module__
                     for cls in bpy.types.RenderEngine.__subclasses__()}
try:
    bpy.context.scene.render.engine = "CSM"
    result["scene_engine"] = bpy.context.scene.render.engine
except TypeError as error:
    result["scene_engine_error"] = str(error)
result["save_userpref"] = sorted(bpy.ops.wm.save_userpref())

# The user's flow: File > Import > CSM Scene of the shipped default scene.
def save_default_scene():
    from csm_engine.core import paths
    # Objects are removed by hand: reading factory settings would also reset the
    # preferences and so disable the add-on just enabled.
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    result["import"] = sorted(bpy.ops.csm.import_scene(filepath=paths.default_scene_path()))
    scene = bpy.context.scene
    result["has_camera"] = scene.camera is not None
    scene.render.resolution_x, scene.render.resolution_y = %(width)d, %(height)d
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.view_settings.view_transform = "Standard"
    # Saved with another engine so that `-E CSM` on the command line is what selects CSM.
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.filepath = "//render_"
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(out_dir, "lit", "scene.blend"))
    suns = [o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
    result["suns"] = len(suns)
    for sun in suns:
        bpy.data.objects.remove(sun)
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(out_dir, "unlit", "scene.blend"))

try:
    save_default_scene()
except Exception:
    import traceback
    result["scene_error"] = traceback.format_exc()
print("CSM_RESULT " + json.dumps(result), flush=True)
''' % {"width": RENDER_SIZE[0], "height": RENDER_SIZE[1]}


@pytest.fixture(scope="module")
def legacy_install(archives, hosts, tmp_path_factory):
    """Blender 3.4 with the legacy zip installed and enabled in saved preferences, plus the
    default scene saved as lit/scene.blend and unlit/scene.blend (sun removed). Shared by
    the tests below: installing once is what a user does, too."""
    blender = hosts.blender_binary()
    host_dir = tmp_path_factory.mktemp("blender34")
    script = host_dir / "legacy_host.py"
    script.write_text(LEGACY_HOST_SCRIPT)
    for name in ("lit", "unlit"):
        (host_dir / name).mkdir()
    env = hosts.user_dirs_env(str(host_dir))
    run = hosts.run_host([blender, "-b", "--factory-startup", "--python-exit-code", "1",
                          "--python", str(script), "--", archives[1], str(host_dir)],
                         env, str(host_dir))
    assert run.returncode == 0 and run.result, f"Blender 3.4 host script failed\n{run.describe()}"
    return blender, env, run, host_dir


def test_legacy_zip_installs_and_enables_in_blender_3_4(legacy_install):
    _, _, run, host_dir = legacy_install
    result = run.result
    assert result["blender"].startswith("3.4"), f"expected Debian's Blender 3.4, got {result['blender']}"
    assert result["install"] == ["FINISHED"] and result["enable"] == ["FINISHED"], run.describe()
    assert "csm_engine" in result["addons"], result["addons"]
    assert result["package_file"].startswith(str(host_dir / "blender-user" / "scripts")), result
    assert result["engines"].get("CSM", "").startswith("csm_engine"), result["engines"]
    assert result.get("scene_engine") == "CSM", result.get("scene_engine_error")
    assert result["save_userpref"] == ["FINISHED"]


def test_blender_3_4_command_line_render_with_csm(legacy_install, hosts):
    blender, env, run, host_dir = legacy_install
    result = run.result
    assert "scene_error" not in result, (
        f"importing the default scene in Blender 3.4 failed:\n{result['scene_error']}")
    assert result["import"] == ["FINISHED"] and result["has_camera"], result
    assert result["suns"] >= 1, "the default scene should have a sun"
    pngs = {}
    for name in ("lit", "unlit"):
        blend = str(host_dir / name / "scene.blend")
        command = [blender, "-b", blend, "-E", "CSM", "-f", "1"]
        run = hosts.run_host(command, env, str(host_dir))
        png = host_dir / name / "render_0001.png"
        assert run.returncode == 0 and png.is_file(), f"render failed or wrote no {png}\n{run.describe()}"
        assert "Traceback" not in run.output, run.describe()
        pngs[name] = str(png)
    _assert_sun_lights_the_frame(pngs["lit"], pngs["unlit"], hosts, "Blender 3.4 -E CSM")


# --- pip bpy hosts: the wheel and its csm-render command ---------------------------------

WHEEL_RENDER = "320x180"
# The default scene from its own camera: the sun lights about 46 % of the frame and the
# ridges and towers shadow about 15 % (320x180); these floors leave wide margins while an
# engine without shadows (0 % shadowed) or without a sun (0 % lit) fails.
MIN_SUNLIT_FRACTION = 0.10
MIN_SHADOWED_FRACTION = 0.02
# In the shaded image, sunlit ground must be brighter than shadowed ground by this much
# (about 0.17 in the default scene; luminance 0..1).
MIN_SHADOW_CONTRAST = 0.05


def _purelib(python):
    result = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                            capture_output=True, text=True, timeout=60, check=True)
    return result.stdout.strip()


def _fresh_venv(host_python, root):
    """A new virtual environment of host_python's Python with nothing installed. A .pth
    appends the host's site-packages so the bpy and numpy users bring are found; csm_engine
    can only come from what is installed into this venv (its own site-packages is first)."""
    venv = os.path.join(root, "venv")
    subprocess.run([host_python, "-m", "venv", "--without-pip", venv], check=True,
                   capture_output=True, timeout=120)
    python = os.path.join(venv, "bin", "python")
    with open(os.path.join(_purelib(python), "host_bpy.pth"), "w") as handle:
        handle.write(_purelib(host_python) + "\n")
    return python


def _pip_install(venv_python, what, cwd):
    """`pip install what` into the venv by .venv's pip, offline and ignoring any pip
    configuration: whatever the package needs must already be there."""
    command = [sys.executable, "-m", "pip", "--isolated", "--python", venv_python, "install",
               "--no-index", "--disable-pip-version-check", "--no-input", what]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=cwd,
                            stdin=subprocess.DEVNULL)
    assert result.returncode == 0, f"{' '.join(command)} failed:\n{result.stdout}{result.stderr}"
    return result


def _installed_package(venv_python, env, cwd):
    script = ("import csm_engine, csm_engine.core.paths as p; "
              "print(csm_engine.__file__); print(p.default_scene_path())")
    result = subprocess.run([venv_python, "-c", script], capture_output=True, text=True,
                            env=env, cwd=cwd, timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout.split()


def _csm_render_from_elsewhere(host_python, wheel, host_dir, hosts, what):
    venv_python = _fresh_venv(host_python, str(host_dir))
    _pip_install(venv_python, wheel, str(host_dir))
    command = os.path.join(os.path.dirname(venv_python), "csm-render")
    assert os.access(command, os.X_OK), f"{what}: pip installed no {command}"
    elsewhere = host_dir / "some other folder"
    elsewhere.mkdir()
    env = hosts.user_dirs_env(str(host_dir))
    venv_root = os.path.dirname(os.path.dirname(venv_python))
    package_file, default_scene = _installed_package(venv_python, env, str(elsewhere))
    assert package_file.startswith(venv_root) and default_scene.startswith(venv_root), (
        f"{what}: csm_engine was not imported from the venv: {package_file}, {default_scene}")

    # What a user types: no arguments renders the bundled scene to ./csm_default.png.
    shaded = hosts.run_host([command, "--resolution", WHEEL_RENDER], env, str(elsewhere))
    assert shaded.returncode == 0, f"{what}: csm-render failed\n{shaded.describe()}"
    assert "Traceback" not in shaded.output, shaded.describe()
    factor = hosts.run_host([command, default_scene, "factor.png", "--resolution", WHEEL_RENDER,
                             "--set", "debug_view=SHADOW_FACTOR"], env, str(elsewhere))
    assert factor.returncode == 0, f"{what}: csm-render failed\n{factor.describe()}"
    broken = hosts.run_host([command, "missing.json", "x.png"], env, str(elsewhere))
    assert broken.returncode == 3, f"{what}: a missing scene should exit 3\n{broken.describe()}"
    assert "csm: error:" in broken.output and "Traceback" not in broken.output, broken.describe()

    shaded_png, factor_png = elsewhere / "csm_default.png", elsewhere / "factor.png"
    assert shaded_png.is_file() and factor_png.is_file(), f"{what}: {os.listdir(elsewhere)}"
    image = hosts.luminance(hosts.read_png(str(shaded_png)))
    visibility = hosts.luminance(hosts.read_png(str(factor_png)))
    width, height = (int(v) for v in WHEEL_RENDER.split("x"))
    assert image.shape == visibility.shape == (height, width), (image.shape, visibility.shape)
    # SHADOW_FACTOR shows the sun's visibility: white where lit, black where shadowed.
    sunlit, shadowed = visibility > 0.9, visibility < 0.1
    assert sunlit.mean() >= MIN_SUNLIT_FRACTION and shadowed.mean() >= MIN_SHADOWED_FRACTION, (
        f"{what}: {sunlit.mean():.1%} sunlit, {shadowed.mean():.1%} shadowed")
    contrast = image[sunlit].mean() - image[shadowed].mean()
    assert contrast >= MIN_SHADOW_CONTRAST, (
        f"{what}: sunlit ground is only {contrast:.3f} brighter than shadowed ground")


def test_wheel_installs_and_csm_render_renders_from_another_folder_in_pip_bpy_5_0(
        archives, host_dir, hosts):
    _csm_render_from_elsewhere(hosts.bpy50_python(), archives[2], host_dir, hosts, "pip bpy 5.0")


def test_wheel_installs_and_csm_render_renders_from_another_folder_in_pip_bpy_4_2(
        archives, host_dir, hosts):
    # pip bpy 4.2 crashes while Python shuts down after a render: the exit code must
    # still be csm-render's own (0 here, 3 for the missing scene).
    _csm_render_from_elsewhere(hosts.bpy42_python(), archives[2], host_dir, hosts, "pip bpy 4.2")


def _tree(root):
    return sorted(os.path.relpath(os.path.join(folder, name), root)
                  for folder, dirs, names in os.walk(root)
                  if "__pycache__" not in folder for name in names)


def test_pip_install_of_a_checkout_installs_what_the_wheel_holds(archives, host_dir, hosts):
    clone = host_dir / "checkout"
    _copy_checkout(str(clone))
    before = _tree(str(clone))
    venv_python = _fresh_venv(hosts.bpy50_python(), str(host_dir))
    _pip_install(venv_python, str(clone), str(host_dir))
    assert _tree(str(clone)) == before, "pip install wrote into the checkout"
    info = _wheel_info_dir(archives[2])
    with open(os.path.join(_purelib(venv_python), info, "RECORD")) as handle:
        # pip compiles what it installs: its .pyc files are listed too, and not shipped.
        installed = {line.split(",")[0] for line in handle
                     if line.startswith("csm_engine/") and "/__pycache__/" not in line}
    with zipfile.ZipFile(archives[2]) as bundle:
        shipped = {n for n in bundle.namelist() if n.startswith("csm_engine/")}
    assert installed == shipped, sorted(installed ^ shipped)
    env = hosts.user_dirs_env(str(host_dir))
    run = hosts.run_host([os.path.join(os.path.dirname(venv_python), "csm-render"), "--help"],
                         env, str(host_dir))
    assert run.returncode == 0 and "usage:" in run.output, run.describe()
