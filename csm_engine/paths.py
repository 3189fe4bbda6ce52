"""Where the add-on's resource folders live.

Owns the lookup of ``shaders/`` and ``data/``. In a built archive they sit inside the
package folder; in a source checkout they sit beside it at the repository root.
"""

import os

PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def _resource_dir(name):
    for candidate in (os.path.join(PACKAGE_DIR, name),
                      os.path.join(os.path.dirname(PACKAGE_DIR), name)):
        if os.path.isdir(candidate):
            return candidate
    raise FileNotFoundError(
        f"CSM Engine: resource folder '{name}' not found next to {PACKAGE_DIR}")


def shaders_dir():
    return _resource_dir("shaders")


def data_dir():
    return _resource_dir("data")


def default_scene_path():
    return os.path.join(data_dir(), "scenes", "default.json")
