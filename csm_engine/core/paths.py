"""Where the add-on's resource folders live.

Owns the lookup of ``shaders/`` and ``data/``. Both sit inside the package, in a source
checkout and in every installed form (extension, legacy add-on, pip), so one lookup serves
them all.
"""

import os

PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _resource_dir(name):
    path = os.path.join(PACKAGE_DIR, name)
    if not os.path.isdir(path):
        raise FileNotFoundError(f"CSM Engine: resource folder '{name}' not found in {PACKAGE_DIR}")
    return path


def shaders_dir():
    return _resource_dir("shaders")


def data_dir():
    return _resource_dir("data")


def default_scene_path():
    return os.path.join(data_dir(), "scenes", "default.json")
