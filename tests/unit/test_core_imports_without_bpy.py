"""The ``core`` folder is the pure part of the engine: it imports with no Blender at all."""
import subprocess
import sys

from tests.conftest import REPO

# A stand-in finder that refuses every Blender module, so the check holds even in a venv
# that has pip bpy installed.
_SCRIPT = r"""
import importlib.abc, pkgutil, sys
BLOCKED = {"bpy", "gpu", "mathutils", "bgl", "bmesh", "bpy_extras", "addon_utils"}
class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ImportError(f"core imported {name}")
        return None
sys.meta_path.insert(0, Refuse())
import csm_engine.core
names = [m.name for m in pkgutil.iter_modules(csm_engine.core.__path__)]
for name in names:
    __import__("csm_engine.core." + name)
loaded = sorted(m for m in sys.modules if m.startswith("csm_engine."))
assert not [m for m in loaded if m.startswith(("csm_engine.render", "csm_engine.blender"))], loaded
print(" ".join(names))
"""


def test_every_core_module_imports_with_bpy_gpu_and_mathutils_absent():
    result = subprocess.run([sys.executable, "-c", _SCRIPT], cwd=REPO, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    modules = set(result.stdout.split())
    assert {"cascades", "camera", "controls", "conventions", "frame", "frame_layout",
            "scene_format", "shadow_plan"} <= modules, modules
