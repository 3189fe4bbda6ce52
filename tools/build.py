"""Build the two CSM Engine archives into dist/.

Owns packaging: one command, ``python tools/build.py``, writes

* ``dist/csm_engine-<version>.zip``: the Blender 4.2+ extension, built and then
  validated by Blender's own extension tool (``bl_pkg/cli/blender_ext.py``, shipped
  inside pip bpy; it is plain Python, so no Blender binary is needed);
* ``dist/csm_engine-<version>-legacy.zip``: the legacy add-on for Blender 3.4-4.1,
  one top-level ``csm_engine/`` folder described by ``bl_info``.

In both archives ``shaders/`` and ``data/`` sit inside the package, which is where
``csm_engine/paths.py`` looks first. Runs on any Python 3.11 with no extra packages;
it only needs a pip bpy install somewhere to find the extension tool (see
``find_extension_tool``). Exit code 0 on success, 1 with a one-line reason otherwise.
"""

import argparse
import fnmatch
import glob
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE_NAME = "csm_engine"
RESOURCE_DIRS = ("shaders", "data")
# Nothing a user's Blender needs: caches, tests and editor droppings.
EXCLUDED_NAMES = ("__pycache__", "*.pyc", "*.pyo", "tests", ".*", "*~", "*.blend1")
EXTENSION_TOOL = os.path.join("scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")
# The tag list Blender itself passes to the tool, so tags are checked as Blender would.
EXTENSION_TAGS = os.path.join("scripts", "modules", "_bpy_internal", "extensions", "tags.py")
# Legacy zip entries get one fixed timestamp so the same sources give the same bytes.
ZIP_TIMESTAMP = (2024, 1, 1, 0, 0, 0)


class BuildError(Exception):
    """A reason the build cannot go on, printed as one line."""


def read_manifest():
    path = os.path.join(REPO_ROOT, "blender_manifest.toml")
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise BuildError(f"cannot read {path}: {error}") from None


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


def _excluded(name):
    return any(fnmatch.fnmatch(name, pattern) for pattern in EXCLUDED_NAMES)


def _copy_tree(source, target):
    shutil.copytree(source, target, ignore=lambda _dir, names: [n for n in names if _excluded(n)])


def stage(staging_dir, with_manifest):
    """Copy the package with its resources into staging_dir (which is emptied first)."""
    if os.path.exists(staging_dir):
        shutil.rmtree(staging_dir)
    package_dir = os.path.join(REPO_ROOT, PACKAGE_NAME)
    if not os.path.isfile(os.path.join(package_dir, "__init__.py")):
        raise BuildError(f"{package_dir}/__init__.py is missing")
    _copy_tree(package_dir, staging_dir)
    for resource in RESOURCE_DIRS:
        source = os.path.join(REPO_ROOT, resource)
        if not os.path.isdir(source):
            raise BuildError(f"resource folder {source} is missing")
        _copy_tree(source, os.path.join(staging_dir, resource))
    # The GPL asks for its text to travel with the code.
    if os.path.isfile(os.path.join(REPO_ROOT, "LICENSE")):
        shutil.copy2(os.path.join(REPO_ROOT, "LICENSE"), staging_dir)
    if with_manifest:
        shutil.copy2(os.path.join(REPO_ROOT, "blender_manifest.toml"), staging_dir)


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


def build_legacy(manifest, dist_dir, staging_root):
    staging_dir = os.path.join(staging_root, "legacy", PACKAGE_NAME)
    stage(staging_dir, with_manifest=False)
    archive = os.path.join(dist_dir, f"{PACKAGE_NAME}-{manifest['version']}-legacy.zip")
    if os.path.exists(archive):
        os.remove(archive)
    parent = os.path.dirname(staging_dir)
    entries = []
    for folder, dirs, files in os.walk(staging_dir):
        dirs.sort()
        entries += [os.path.join(folder, name) for name in sorted(files)]
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as bundle:
        for path in entries:
            info = zipfile.ZipInfo(os.path.relpath(path, parent).replace(os.sep, "/"), ZIP_TIMESTAMP)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with open(path, "rb") as handle:
                bundle.writestr(info, handle.read())
    return archive


def check_versions_agree(manifest):
    """The manifest and bl_info must name one version, or the two archives would differ."""
    init_path = os.path.join(REPO_ROOT, PACKAGE_NAME, "__init__.py")
    import ast
    with open(init_path, encoding="utf-8") as handle:
        tree = ast.parse(handle.read(), init_path)
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                getattr(target, "id", None) == "bl_info" for target in node.targets):
            bl_version = ast.literal_eval(node.value)["version"]
            manifest_version = tuple(int(p) for p in manifest["version"].split("."))
            if tuple(bl_version) != manifest_version:
                raise BuildError(
                    f"version mismatch: blender_manifest.toml says {manifest['version']}, "
                    f"bl_info in {init_path} says {bl_version}")
            return
    raise BuildError(f"no bl_info found in {init_path}")


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
        legacy = build_legacy(manifest, dist_dir, staging_root)
    except BuildError as error:
        print(f"build.py: error: {error}", file=sys.stderr)
        return 1
    finally:
        shutil.rmtree(staging_root, ignore_errors=True)
    print(f"extension (Blender 4.2+, validated by {tool}):")
    print(f"  {extension}")
    print("legacy add-on (Blender 3.4-4.1):")
    print(f"  {legacy}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
