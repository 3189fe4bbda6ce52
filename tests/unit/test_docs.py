"""The user documentation agrees with the add-on and holds together.

- ``docs/settings.md`` is exactly what ``tools/make_settings_reference.py`` writes from the
  settings model today (so every default, range, unit and choice on it is the model's),
  and it names every setting, each with a "when to change it" note.
- A setting's default stated elsewhere in the docs as "`identifier` (default X)" or
  "Label (default X)" is the model's default.
- Every relative link and picture in README.md and docs/ points to a file in the
  repository; no link leaves it.
"""

import importlib.util
import re
from pathlib import Path

import pytest

from csm_engine.core import settings_model
from csm_engine.core.settings_model import SETTINGS

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.rglob("*.md")) + [ROOT / "README.md"]


def _generator():
    spec = importlib.util.spec_from_file_location(
        "make_settings_reference", ROOT / "tools" / "make_settings_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_settings_reference_is_generated_from_the_model():
    expected = _generator().render()
    current = (DOCS / "settings.md").read_text(encoding="utf-8")
    assert current == expected, (
        "docs/settings.md differs from the settings model: run "
        "python tools/make_settings_reference.py")


def test_settings_reference_names_every_setting():
    text = (DOCS / "settings.md").read_text(encoding="utf-8")
    for setting in SETTINGS:
        assert f"### {setting.name} (`{setting.identifier}`)" in text, setting.identifier
        for item in setting.items:
            assert f"`{item.identifier}`" in text, (setting.identifier, item.identifier)


def test_every_setting_has_a_note_and_no_note_is_stale():
    generator = _generator()
    identifiers = {setting.identifier for setting in SETTINGS}
    assert set(generator.WHEN) == identifiers
    assert set(generator.UNITS) <= identifiers
    assert set(generator.PICTURES) <= identifiers
    for image, _caption in generator.PICTURES.values():
        assert (DOCS / "images" / image).is_file(), image


def _stated_value(setting, text):
    """The model's way of writing a default, and the text's, made comparable."""
    text = text.strip().strip("`*").strip()
    if setting.kind == settings_model.BOOLEAN:
        return {"on": True, "true": True, "off": False, "false": False}.get(text.lower(), text)
    if setting.kind == settings_model.ENUM:
        for item in setting.items:
            if text in (item.identifier, item.label):
                return item.identifier
        return text
    if setting.kind == settings_model.FLOAT_VECTOR:
        try:
            return tuple(float(v) for v in re.split(r"\s*[/,]\s*", text))
        except ValueError:
            return text
    try:
        return float(text)
    except ValueError:
        return text


def _model_value(setting):
    if setting.kind in (settings_model.INT, settings_model.FLOAT):
        return float(setting.default)
    return setting.default


def _stated_defaults():
    """(page, setting, stated text) for every "X (default V)" or "X (..., default V)" in
    the docs, X being a setting's identifier in backquotes or its label."""
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for setting in SETTINGS:
            names = [re.escape(f"`{setting.identifier}`"), re.escape(f"**{setting.name}**"),
                     r"(?<![\w(*`])" + re.escape(setting.name) + r"(?![\w(*`])"]
            for bare, name in zip((False, False, True), names):
                # "Name (default V)", "Name (metres, default V)"
                pattern = (name + r"\s*\((?:[^()]{0,80}?[,;]\s*)?default:?\s*"
                           r"([^,;:)]+)[,;:)]")
                for match in re.finditer(pattern, text):
                    # A bare label is not taken as the tail of a longer one ("Distance"
                    # in "Shadow Distance", "Lambda" in "Lambda (Fitted)").
                    before = text[max(match.start() - 30, 0):match.start()]
                    if bare and re.search(r"[A-Z][\w-]*[ ]$", before):
                        continue
                    found.append((page.relative_to(ROOT).as_posix(), setting, match.group(1)))
    return found


def _agrees(setting, stated):
    """Whether ``stated`` is the default of ``setting`` or of a setting with the same label
    (the Cascades and Light panels each have a "Distance")."""
    return any(_stated_value(other, stated) == _model_value(other) for other in SETTINGS
               if other is setting or other.name == setting.name)


def test_defaults_stated_in_the_docs_are_the_models():
    wrong = [f"{page}: {setting.identifier} stated as {stated!r}, the model says "
             f"{setting.default!r}"
             for page, setting, stated in _stated_defaults()
             if not _agrees(setting, stated)]
    assert not wrong, "\n".join(wrong)


def test_the_default_check_sees_the_docs():
    # The check above must have something to compare, or it would pass on any text.
    assert len(_stated_defaults()) >= 5


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _links():
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        # Fenced code is not a link.
        text = re.sub(r"```.*?```", "", text, flags=re.S)
        for match in LINK.finditer(text):
            yield page, match.group(1)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_point_to_files_in_the_repository(page):
    broken = []
    for source, target in _links():
        if source != page or re.match(r"[a-z]+:", target):
            continue
        file_part, _, fragment = target.partition("#")
        path = (page.parent / file_part).resolve() if file_part else page.resolve()
        if ROOT.resolve() not in path.parents and path != ROOT.resolve():
            broken.append(f"{target} (outside the repository)")
        elif not path.exists():
            broken.append(target)
        elif fragment and path.suffix == ".md" and fragment not in _anchors(path):
            broken.append(f"{target} (no such heading)")
    assert not broken, f"{page.relative_to(ROOT)}: broken links {broken}"


def _anchors(path):
    """The anchors GitHub gives a page's headings: lower case, punctuation dropped,
    spaces to hyphens."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    anchors = set()
    for heading in re.findall(r"^#+\s+(.*)$", text, flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        anchors.add(slug)
    return anchors


def test_readme_starts_with_the_two_commands():
    # Newcomers and CI read the top of the README: the title, then how to render and test.
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "# CSM Engine"
    block = lines[lines.index("```sh") + 1:lines.index("```", lines.index("```sh") + 1)]
    assert [line.split()[:2] for line in block] == [["./dev", "render"], ["./dev", "test"]]
    assert lines.index("```sh") == 2


def test_the_guide_is_reachable_from_the_readme():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for page in ("getting-started", "viewport", "settings", "course-assignment",
                 "troubleshooting", "techniques"):
        assert f"(docs/{page}.md)" in readme, page
