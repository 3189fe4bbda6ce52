"""docs/architecture.md stays true about what exists: every shipped Python module, every
GLSL file and every top-level folder it describes is there, and everything that is there
is described."""
import re
from pathlib import Path

from tests.conftest import REPO

ROOT = Path(REPO)
DOC = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
NAMED = set(re.findall(r"`([\w/.]+\.(?:py|glsl))`", DOC))


def _described(path):
    """Whether the doc names this file (by name, as its tables do, or by its path)."""
    return path.name in NAMED or str(path.relative_to(ROOT)) in NAMED or any(
        name.endswith("/" + path.name) for name in NAMED)


def test_every_module_and_shader_is_described():
    files = sorted(p for p in (ROOT / "csm_engine").rglob("*.py") if p.name != "__init__.py")
    files += sorted((ROOT / "shaders").glob("*.glsl"))
    files += sorted(p for p in (ROOT / "tools" / "csm_tools").glob("*.py")
                    if p.name != "__init__.py")
    missing = [str(p.relative_to(ROOT)) for p in files if not _described(p)]
    assert not missing, f"docs/architecture.md does not describe {missing}"


def test_every_file_the_doc_names_exists():
    existing = {p.name for p in ROOT.rglob("*") if p.suffix in (".py", ".glsl")
                and ".venv" not in p.parts and "dist" not in p.parts}
    ghosts = sorted(name for name in NAMED if Path(name).name not in existing)
    assert not ghosts, f"docs/architecture.md names files that do not exist: {ghosts}"
