"""Repository-wide test settings: where the checkout and its bundled data are.

The one definition of the repository root for every test (``from tests.conftest import
REPO``). Host scripts that run inside another Blender (``hosts/gui_*driver.py``) locate the
checkout from their own file instead, since they are not imported by pytest.
"""
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(REPO, "csm_engine")
DATA = os.path.join(PACKAGE, "data")
SCENES = os.path.join(DATA, "scenes")
DEFAULT_SCENE = os.path.join(SCENES, "default.json")
TOOLS = os.path.join(REPO, "tools")

# The measuring tools live outside the add-on, in tools/csm_tools.
for path in (REPO, TOOLS):
    if path not in sys.path:
        sys.path.insert(0, path)
