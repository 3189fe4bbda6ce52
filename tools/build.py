"""Build CSM Engine's three packages into dist/, and be pip's build backend.

Owns packaging: one command, ``python tools/build.py`` (``./dev build``), writes

* ``dist/csm_engine-<version>.zip``: the Blender 4.2+ extension, built and then
  validated by Blender's own extension tool (``bl_pkg/cli/blender_ext.py``, shipped
  inside pip bpy; it is plain Python, so no Blender binary is needed);
* ``dist/csm_engine-<version>-legacy.zip``: the legacy add-on for Blender 3.4-4.1,
  one top-level ``csm_engine/`` folder described by ``bl_info``;
* ``dist/csm_engine-<version>-py3-none-any.whl``: the Python package for pip bpy users,
  with the ``csm-render`` command (``python -m csm_engine``).

All three carry the ``csm_engine`` package as it is in the checkout (``data/`` lives inside
it), the repository's top-level GLSL library ``shaders/`` placed inside the package as
``csm_engine/shaders/`` (an installed add-on or wheel is one folder; ``core/paths.py``
finds the GLSL in either place), plus ``LICENSE``; the measuring tools
(``tools/csm_tools``) and tests are never in it. The same module is the PEP 517 backend named in ``pyproject.toml``
(``build_wheel``, ``build_sdist``), so ``pip install <checkout>`` makes the very wheel
``./dev build`` does, offline and with nothing but the standard library. Runs on any
Python 3.11; only the extension needs a pip bpy install somewhere, for Blender's tool
(see ``find_extension_tool``). Exit code 0 on success, 1 with a one-line reason otherwise.
"""

import argparse
import ast
import base64
import fnmatch
import glob
import hashlib
import io
import os
import shutil
import subprocess
import sys
import sysconfig
import tarfile
import tomllib
import zipfile

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE_NAME = "csm_engine"
# The GLSL library: a top-level folder of the checkout, shipped inside the package.
SHADERS_DIR = "shaders"
# What the package cannot work without (relative to the package folder, as shipped); a
# checkout missing one is refused, not shipped.
REQUIRED_RESOURCES = (os.path.join(SHADERS_DIR, "lighting_frag.glsl"),
                      os.path.join("data", "scenes", "default.json"))
# Nothing a user's Blender needs: caches, tests and editor droppings.
EXCLUDED_NAMES = ("__pycache__", "*.pyc", "*.pyo", "tests", ".*", "*~", "*.blend1")
EXTENSION_TOOL = os.path.join("scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")
# The tag list Blender itself passes to the tool, so tags are checked as Blender would.
EXTENSION_TAGS = os.path.join("scripts", "modules", "_bpy_internal", "extensions", "tags.py")
# Legacy zip, wheel and sdist entries get one fixed timestamp so the same sources give
# the same bytes.
ZIP_TIMESTAMP = (2024, 1, 1, 0, 0, 0)
# The [project] keys the wheel metadata is written from; any other key is refused so a
# setting added to pyproject.toml can never be silently dropped from the wheel.
PROJECT_KEYS = {"name", "dynamic", "description", "readme", "requires-python", "license",
                "authors", "classifiers", "keywords", "dependencies",
                "optional-dependencies", "scripts", "urls"}


class BuildError(Exception):
    """A reason the build cannot go on, printed as one line."""


# -- sources --------------------------------------------------------------------------------

def read_manifest(root=REPO_ROOT):
    path = os.path.join(root, "blender_manifest.toml")
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise BuildError(f"cannot read {path}: {error}") from None


def read_bl_info_version(root=REPO_ROOT):
    """``bl_info["version"]`` from the package's __init__.py, read without importing it."""
    init_path = os.path.join(root, PACKAGE_NAME, "__init__.py")
    with open(init_path, encoding="utf-8") as handle:
        tree = ast.parse(handle.read(), init_path)
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                getattr(target, "id", None) == "bl_info" for target in node.targets):
            return tuple(ast.literal_eval(node.value)["version"])
    raise BuildError(f"no bl_info found in {init_path}")


def check_versions_agree(manifest, root=REPO_ROOT):
    """The manifest's version is the one version; bl_info must name it too (Blender reads
    bl_info as a literal, so it cannot be derived), or the archives would differ."""
    bl_version = read_bl_info_version(root)
    manifest_version = tuple(int(p) for p in manifest["version"].split("."))
    if bl_version != manifest_version:
        raise BuildError(
            f"version mismatch: blender_manifest.toml says {manifest['version']}, "
            f"bl_info in {PACKAGE_NAME}/__init__.py says {bl_version}")
    return manifest["version"]


def _excluded(name):
    return any(fnmatch.fnmatch(name, pattern) for pattern in EXCLUDED_NAMES)


def _walk(top, inside):
    """(absolute path, ``inside``/relative path) of every shipped file under ``top``."""
    found = []
    for folder, dirs, names in os.walk(top):
        dirs[:] = sorted(d for d in dirs if not _excluded(d))
        for name in sorted(names):
            if not _excluded(name):
                path = os.path.join(folder, name)
                relative = os.path.relpath(path, top).replace(os.sep, "/")
                found.append((path, f"{inside}/{relative}" if inside else relative))
    return found


def package_files(root=REPO_ROOT):
    """(absolute path, path inside the package folder) of every file every package ships,
    sorted: the csm_engine package with its data, the top-level shaders/ as the package's
    shaders/, and LICENSE at its root."""
    package_dir = os.path.join(root, PACKAGE_NAME)
    shaders_dir = os.path.join(root, SHADERS_DIR)
    if not os.path.isfile(os.path.join(package_dir, "__init__.py")):
        raise BuildError(f"{package_dir}/__init__.py is missing")
    # A checkout keeps the GLSL in one place only: two copies would both go into the
    # archives under one name.
    stray = os.path.join(package_dir, SHADERS_DIR)
    if os.path.exists(stray):
        raise BuildError(f"{stray} exists: the GLSL lives in the top-level {SHADERS_DIR}/ "
                         "(move any edits there and delete that folder)")
    files = _walk(package_dir, "") + _walk(shaders_dir, SHADERS_DIR)
    shipped = {relative for _, relative in files}
    for resource in REQUIRED_RESOURCES:
        if resource.replace(os.sep, "/") not in shipped:
            top = root if resource.startswith(SHADERS_DIR) else package_dir
            raise BuildError(f"{os.path.join(top, resource)} is missing")
    # The GPL asks for its text to travel with the code.
    license_path = os.path.join(root, "LICENSE")
    if not os.path.isfile(license_path):
        raise BuildError(f"{license_path} is missing (the manifest declares GPL-3.0-or-later)")
    files.append((license_path, "LICENSE"))
    return sorted(files, key=lambda item: item[1])


def stage(staging_dir, with_manifest, root=REPO_ROOT):
    """Copy the shipped files into staging_dir (which is emptied first)."""
    if os.path.exists(staging_dir):
        shutil.rmtree(staging_dir)
    for source, relative in package_files(root):
        target = os.path.join(staging_dir, relative)
        os.makedirs(os.path.dirname(target), exist_ok=True)
        shutil.copy2(source, target)
    if with_manifest:
        shutil.copy2(os.path.join(root, "blender_manifest.toml"), staging_dir)


def _zip_info(name):
    info = zipfile.ZipInfo(name, ZIP_TIMESTAMP)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    return info


def _read(path):
    with open(path, "rb") as handle:
        return handle.read()


# -- Blender archives -----------------------------------------------------------------------

def _bpy_version_key(tool_path):
    # .../site-packages/bpy/<major.minor>/scripts/... : prefer the newest Blender's tool.
    version_dir = tool_path.split(os.sep + "bpy" + os.sep)[-1].split(os.sep)[0]
    try:
        return tuple(int(part) for part in version_dir.split("."))
    except ValueError:
        return (0,)


def find_extension_tool():
    """Path of Blender's blender_ext.py: $CSM_BLENDER_EXT, else the newest pip bpy found
    in this interpreter, the repository's virtual environments or $CSM_BPY_SITE_PACKAGES."""
    override = os.environ.get("CSM_BLENDER_EXT")
    if override:
        if not os.path.isfile(override):
            raise BuildError(f"CSM_BLENDER_EXT={override} is not a file")
        return override
    site_dirs = [sysconfig.get_path("purelib"), sysconfig.get_path("platlib")]
    site_dirs += glob.glob(os.path.join(REPO_ROOT, ".venv*", "lib", "python3*", "site-packages"))
    site_dirs += [d for d in os.environ.get("CSM_BPY_SITE_PACKAGES", "").split(os.pathsep) if d]
    found = []
    for site_dir in dict.fromkeys(site_dirs):
        found += glob.glob(os.path.join(site_dir, "bpy", "*", EXTENSION_TOOL))
    if not found:
        raise BuildError(
            "Blender's extension tool (bpy/<version>/" + EXTENSION_TOOL.replace(os.sep, "/")
            + ") was not found: install pip bpy (./dev build does) or set CSM_BLENDER_EXT")
    return max(found, key=_bpy_version_key)


def run_extension_tool(tool, tags, *args):
    command = [sys.executable, tool, *args, "--valid-tags", tags]
    result = subprocess.run(command, capture_output=True, text=True)
    output = (result.stdout + result.stderr).strip()
    if result.returncode != 0:
        raise BuildError(f"blender_ext.py {args[0]} failed: {output}")
    return output


def build_extension(manifest, dist_dir, staging_root):
    tool = find_extension_tool()
    tags = os.path.join(tool.split(os.sep + "scripts" + os.sep)[0], EXTENSION_TAGS)
    staging_dir = os.path.join(staging_root, "extension")
    stage(staging_dir, with_manifest=True)
    archive = os.path.join(dist_dir, f"{manifest['id']}-{manifest['version']}.zip")
    if os.path.exists(archive):
        os.remove(archive)
    run_extension_tool(tool, tags, "build", "--source-dir", staging_dir,
                       "--output-filepath", archive)
    # Validate the archive itself, as a user's Blender would read it.
    run_extension_tool(tool, tags, "validate", archive)
    return archive, tool


def build_legacy(manifest, dist_dir):
    archive = os.path.join(dist_dir, f"{PACKAGE_NAME}-{manifest['version']}-legacy.zip")
    if os.path.exists(archive):
        os.remove(archive)
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as bundle:
        for path, relative in package_files():
            bundle.writestr(_zip_info(f"{PACKAGE_NAME}/{relative}"), _read(path))
    return archive


# -- Python wheel and sdist (PEP 517 backend) -----------------------------------------------

def read_project(root=REPO_ROOT):
    """pyproject.toml's [project] table, checked against what this backend writes."""
    path = os.path.join(root, "pyproject.toml")
    try:
        with open(path, "rb") as handle:
            project = tomllib.load(handle)["project"]
    except (OSError, KeyError, tomllib.TOMLDecodeError) as error:
        raise BuildError(f"cannot read [project] from {path}: {error!r}") from None
    unknown = sorted(set(project) - PROJECT_KEYS)
    if unknown:
        raise BuildError(f"{path}: [project] keys {unknown} are not written by tools/build.py; "
                         "teach write_metadata about them first")
    if project.get("dynamic") != ["version"] or "version" in project:
        raise BuildError(f"{path}: the version must be dynamic = [\"version\"]: it is "
                         "blender_manifest.toml's")
    return project


def distribution_name(project):
    # The wheel and .dist-info spelling of the project name (PEP 427 / PEP 503).
    return project["name"].replace("-", "_").replace(".", "_").lower()


def write_metadata(project, version, root=REPO_ROOT):
    """Core metadata (METADATA / PKG-INFO) text, version 2.1."""
    lines = ["Metadata-Version: 2.1", f"Name: {project['name']}", f"Version: {version}"]
    if "description" in project:
        lines.append(f"Summary: {project['description']}")
    for author in project.get("authors", []):
        if "name" in author:
            lines.append(f"Author: {author['name']}")
        if "email" in author:
            lines.append(f"Author-email: {author['email']}")
    license_text = project.get("license", {}).get("text")
    if license_text:
        lines.append(f"License: {license_text}")
    if project.get("keywords"):
        lines.append("Keywords: " + ",".join(project["keywords"]))
    lines += [f"Classifier: {c}" for c in project.get("classifiers", [])]
    lines += [f"Project-URL: {k}, {v}" for k, v in project.get("urls", {}).items()]
    if "requires-python" in project:
        lines.append(f"Requires-Python: {project['requires-python']}")
    lines += [f"Requires-Dist: {d}" for d in project.get("dependencies", [])]
    for extra, requirements in project.get("optional-dependencies", {}).items():
        lines.append(f"Provides-Extra: {extra}")
        lines += [f'Requires-Dist: {d}; extra == "{extra}"' for d in requirements]
    body = ""
    if "readme" in project:
        readme = project["readme"]
        if not (isinstance(readme, str) and readme.endswith(".md")):
            raise BuildError(f"pyproject.toml: readme must be a .md file name, got {readme!r}")
        lines.append("Description-Content-Type: text/markdown")
        body = "\n" + _read(os.path.join(root, readme)).decode("utf-8")
    return "\n".join(lines) + "\n" + body


def _record_line(name, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    """PEP 517 hook, also used by ``./dev build``: write the wheel, return its file name."""
    project = read_project()
    version = check_versions_agree(read_manifest())
    dist = distribution_name(project)
    info_dir = f"{dist}-{version}.dist-info"
    entries = [(f"{PACKAGE_NAME}/{relative}", _read(path))
               for path, relative in package_files() if relative != "LICENSE"]
    entries.append((f"{info_dir}/LICENSE", _read(os.path.join(REPO_ROOT, "LICENSE"))))
    entries.append((f"{info_dir}/METADATA", write_metadata(project, version).encode()))
    entries.append((f"{info_dir}/WHEEL", (
        "Wheel-Version: 1.0\nGenerator: csm_engine tools/build.py\n"
        "Root-Is-Purelib: true\nTag: py3-none-any\n").encode()))
    scripts = project.get("scripts", {})
    if scripts:
        text = "[console_scripts]\n" + "".join(f"{k} = {v}\n" for k, v in scripts.items())
        entries.append((f"{info_dir}/entry_points.txt", text.encode()))
    entries.append((f"{info_dir}/top_level.txt", f"{PACKAGE_NAME}\n".encode()))
    record = "".join(_record_line(name, data) + "\n" for name, data in entries)
    record += f"{info_dir}/RECORD,,\n"
    entries.append((f"{info_dir}/RECORD", record.encode()))

    os.makedirs(wheel_directory, exist_ok=True)
    wheel_name = f"{dist}-{version}-py3-none-any.whl"
    path = os.path.join(wheel_directory, wheel_name)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as wheel:
        for name, data in entries:
            wheel.writestr(_zip_info(name), data)
    return wheel_name


def get_requires_for_build_wheel(config_settings=None):
    return []


def get_requires_for_build_sdist(config_settings=None):
    return []


def build_sdist(sdist_directory, config_settings=None):
    """PEP 517 hook: a source archive from which build_wheel makes the same wheel."""
    project = read_project()
    version = check_versions_agree(read_manifest())
    base = f"{distribution_name(project)}-{version}"
    # The checkout's own layout (shaders/ at the top), from which build_wheel runs again.
    files = [(path, os.path.relpath(path, REPO_ROOT).replace(os.sep, "/"))
             for path, relative in package_files() if relative != "LICENSE"]
    for name in ("LICENSE", "pyproject.toml", "blender_manifest.toml", project.get("readme"),
                 os.path.join("tools", "build.py")):
        if name:
            files.append((os.path.join(REPO_ROOT, name), name.replace(os.sep, "/")))
    entries = [(name, _read(path)) for path, name in files]
    entries.append(("PKG-INFO", write_metadata(project, version).encode()))
    os.makedirs(sdist_directory, exist_ok=True)
    sdist_name = f"{base}.tar.gz"
    mtime = 1704067200   # ZIP_TIMESTAMP as a Unix time
    with tarfile.open(os.path.join(sdist_directory, sdist_name), "w:gz",
                      format=tarfile.PAX_FORMAT) as archive:
        for name, data in sorted(entries):
            info = tarfile.TarInfo(f"{base}/{name}")
            info.size, info.mtime, info.mode = len(data), mtime, 0o644
            archive.addfile(info, io.BytesIO(data))
    return sdist_name


# -- command line ---------------------------------------------------------------------------

def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dist", default=os.path.join(REPO_ROOT, "dist"),
                        help="output folder (default: <repo>/dist)")
    args = parser.parse_args(argv)
    dist_dir = os.path.abspath(args.dist)
    staging_root = os.path.join(dist_dir, ".staging")
    try:
        manifest = read_manifest()
        check_versions_agree(manifest)
        os.makedirs(dist_dir, exist_ok=True)
        extension, tool = build_extension(manifest, dist_dir, staging_root)
        legacy = build_legacy(manifest, dist_dir)
        wheel = os.path.join(dist_dir, build_wheel(dist_dir))
    except BuildError as error:
        print(f"build.py: error: {error}", file=sys.stderr)
        return 1
    finally:
        shutil.rmtree(staging_root, ignore_errors=True)
    print(f"extension (Blender 4.2+, validated by {tool}):")
    print(f"  {extension}")
    print("legacy add-on (Blender 3.4-4.1):")
    print(f"  {legacy}")
    print("Python wheel (pip bpy; `pip install` it for the csm-render command):")
    print(f"  {wheel}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
