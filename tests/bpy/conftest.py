"""In-process tests on pip bpy: the add-on is registered from this checkout once per session.

Helpers here build small scenes and render them with CSM, returning numpy images, so each
test reads like what a user would check by eye.
"""

import bpy
import pytest


_EXIT_STATUS = {}


def pytest_sessionfinish(session, exitstatus):
    _EXIT_STATUS["code"] = int(exitstatus)


def pytest_unconfigure(config):
    # pip bpy 4.2 segfaults while Python shuts down after a GPU-context render, which would
    # turn the suite's exit code into 139; leave with pytest's own code once it has printed
    # everything (see csm_engine.blender.compat.exit_process). 5.0 shuts down cleanly.
    if bpy.app.version < (5, 0, 0) and "code" in _EXIT_STATUS:
        from csm_engine.blender.compat import exit_process
        exit_process(_EXIT_STATUS["code"])


@pytest.fixture(scope="session", autouse=True)
def csm_registered():
    import csm_engine
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "csm"):
        csm_engine.register()
    yield
    # Leave registration in place: bpy cannot be re-imported in one process.


@pytest.fixture
def empty_scene():
    """A clean scene with CSM as engine and the plain sRGB view transform."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CSM"
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_percentage = 100
    return scene
