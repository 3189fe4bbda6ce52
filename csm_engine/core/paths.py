"""Where the add-on's resource folders live.

Owns the lookup of the GLSL library (``shaders/``) and the bundled data (``data/``).

``data/`` sits inside the package everywhere. The GLSL lives in the repository's top-level
``shaders/``, beside the package, in a source checkout; every installed form (extension,
legacy add-on, wheel) carries it inside the package as ``csm_engine/shaders/``, because
Blender and pip install one folder. ``shaders_dir`` looks inside the package first, so an
installed add-on always reads (and F5 reloads) its own installed copy, and a checkout reads
the top-level folder it is edited in. A user can point the add-on at another copy (the
Shader Folder preference, see ``render/shaders.py``); ``shaders_dir`` is the add-on's own.

Also owns how a folder is shown in a narrow panel (``display_path``).
"""

import os

PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The repository root of a source checkout (or whatever folder holds an installed package).
CHECKOUT_DIR = os.path.dirname(PACKAGE_DIR)
# A file every GLSL library holds: a folder without it is not ours (a stray ``shaders/``
# next to an installed package, say).
SHADER_MARKER = "lighting_frag.glsl"


def _resource_dir(name):
    path = os.path.join(PACKAGE_DIR, name)
    if not os.path.isdir(path):
        raise FileNotFoundError(f"CSM Engine: resource folder '{name}' not found in {PACKAGE_DIR}")
    return path


def shader_dir_candidates():
    """The folders ``shaders_dir`` considers, in order: the installed copy inside the
    package, then a checkout's top-level ``shaders/``."""
    return (os.path.join(PACKAGE_DIR, "shaders"), os.path.join(CHECKOUT_DIR, "shaders"))


def shaders_dir():
    """The add-on's own GLSL library: what it reads (and F5 reloads) unless the user's
    Shader Folder preference names another."""
    candidates = shader_dir_candidates()
    for path in candidates:
        if os.path.isfile(os.path.join(path, SHADER_MARKER)):
            return path
    raise FileNotFoundError("CSM Engine: the GLSL library (shaders/ with "
                            f"{SHADER_MARKER}) is in neither {' nor '.join(candidates)}")


def display_path(path, max_chars=30):
    """``path`` short enough for a panel line: the home folder as ``~``, and when still too
    long the last folders that fit after ``…/`` (the end of a path tells copies apart:
    ``…/my-checkout/shaders``). The last folder is kept whole however long it is."""
    path = os.path.normpath(path)
    home = os.path.expanduser("~")
    if home not in ("~", os.sep) and (path == home or path.startswith(home + os.sep)):
        path = "~" + path[len(home):]
    if len(path) <= max_chars:
        return path
    parts = path.split(os.sep)
    shown = parts[-1]
    for part in reversed(parts[:-1]):
        if len(part) + 1 + len(shown) + 2 > max_chars:
            break
        shown = part + os.sep + shown
    return "\u2026" + os.sep + shown


def data_dir():
    return _resource_dir("data")


def default_scene_path():
    return os.path.join(data_dir(), "scenes", "default.json")
