"""History lives in git, not in the product: no session numbers, issue numbers or commit
hashes in the code, shaders, docs, tests, tools or README.

Comments and docs say why something is so and, for a measurement, the command and the date
it was measured; which working session or commit it came from is what ``git log`` is for.
The scan reads every text file under the folders below and reports each hit as
``path:line: text`` so one run lists everything left to mend.

The patterns are assembled from word lists at import time so this file never contains the
phrases it looks for.
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# Folders and files scanned (a missing one, e.g. shaders/ before the GLSL moves, is skipped).
SCANNED = ("csm_engine", "shaders", "docs", "tests", "tools", "README.md")

# Text files only: images, meshes and archives cannot carry a comment.
TEXT_SUFFIXES = {
    ".py", ".glsl", ".vert", ".frag", ".md", ".txt", ".toml", ".json", ".gltf", ".obj",
    ".ply", ".mtl", ".patch", ".diff", ".ini", ".cfg", ".sh", ".yml", ".yaml", ".csv",
}
SKIPPED_DIRS = {"__pycache__", ".pytest_cache", ".hypothesis"}

# Explicit exceptions, each as (path relative to the repository, exact hit text). Keep this
# list short: a hit is almost always something to rephrase, not to allow.
ALLOWED = set()

_ORDINALS = (
    "first second third fourth fifth sixth seventh eighth ninth tenth eleventh twelfth "
    "thirteenth fourteenth fifteenth sixteenth seventeenth eighteenth nineteenth "
    "twentieth thirtieth"
).split()
_ORDINAL = r"(?:" + "|".join(_ORDINALS) + r"|\d+(?:st|nd|rd|th))"
_WORD = "sess" + "ion"

PATTERNS = [
    # "the <ordinal> <word>", "<ordinal> <word>'s", also across a comment's line break
    ("session number", re.compile(
        r"\b" + _ORDINAL + r"(?:[\s*#/-]*\s[\s*#/-]*|-)" + _WORD + r"s?\b", re.IGNORECASE)),
    # "<word> N", "<word>s N-M", "<word> #N"
    ("session number", re.compile(r"\b" + _WORD + r"s?\s+#?\d+\b", re.IGNORECASE)),
    # "issue N", "issues #N", "pull request N", "PR N"
    ("issue number", re.compile(
        r"\b(?:iss" + r"ues?|pull\s+requests?|PRs?)\s*#?\d+\b", re.IGNORECASE)),
    # a bare "#N" after a space or bracket (a colour is hex and 3, 4, 6 or 8 long; a
    # preprocessor line is "#define")
    ("issue number", re.compile(r"(?:^|(?<=[\s(\[,;]))#\d{1,5}\b(?![0-9a-fA-F])")),
    # GitHub links to issues and pull requests
    ("issue link", re.compile(r"/(?:iss" + r"ues|pull)/\d+\b")),
]

# A commit hash: 7-40 hex digits with both a letter and a digit, in a context that names a
# commit: after "commit", "main", "at", "on", "from", "since", "index", "rev" or "sha",
# inside parentheses or backquotes, or in a range "a..b". Numbers, hex constants ("0x..."),
# colours ("#a0b1c2") and 64-digit digests do not match.
_HEX = r"(?<![#\w])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}(?!\w)"
_CONTEXT_BEFORE = (
    r"(?:\b(?i:commits?|main|master|head|at|on|from|since|index|rev|revision|sha|hash|"
    r"branch|before|after|against|vs\.?)\s+[`(]?|[(`]|\.\.\.?)"
)
_CONTEXT_AFTER = r"(?:[)`]|\.\.)"
HASH_PATTERN = re.compile(
    r"(?:" + _CONTEXT_BEFORE + r")" + _HEX + r"|" + _HEX + r"(?=" + _CONTEXT_AFTER + r")")


def find_history(text):
    """(1-based line, kind, matched text) for every history reference in ``text``."""
    hits = set()
    for kind, pattern in PATTERNS + [("commit hash", HASH_PATTERN)]:
        for match in pattern.finditer(text):
            line = text.count("\n", 0, match.start()) + 1
            hits.add((line, kind, " ".join(match.group(0).split())))
    return sorted(hits)


def scanned_files():
    for name in SCANNED:
        path = ROOT / name
        if path.is_file():
            yield path
        elif path.is_dir():
            for child in sorted(path.rglob("*")):
                if (child.is_file() and child.suffix.lower() in TEXT_SUFFIXES
                        and not SKIPPED_DIRS.intersection(child.relative_to(ROOT).parts)):
                    yield child


def read_text(path):
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        return None


def test_no_session_issue_or_commit_references():
    hits = []
    for path in scanned_files():
        text = read_text(path)
        if text is None:
            continue
        relative = path.relative_to(ROOT).as_posix()
        lines = text.splitlines()
        for line, kind, found in find_history(text):
            if (relative, found) in ALLOWED:
                continue
            source = lines[line - 1].strip() if line <= len(lines) else ""
            hits.append(f"{relative}:{line}: {kind} {found!r}: {source[:160]}")
    assert not hits, (f"{len(hits)} history references (git keeps history; say why, or "
                      f"the command and date of a measurement):\n" + "\n".join(hits))


# --- the detector itself -----------------------------------------------------------------
# The examples are glued together from pieces so this file holds none of them whole.

def _joined(*parts):
    return "".join(parts)


@pytest.mark.parametrize("text", [
    _joined("measured in the ", "tenth", " ", _WORD, " on 2026-11-24"),
    _joined("the ", "Eleventh", " ", _WORD, "'s references"),
    _joined("until the ", "sixth", "\n * ", _WORD, " the blur ran"),
    _joined("# until the ", "twelfth", "\n    # ", _WORD, ")"),
    _joined(_WORD.title(), " 12 measured"),
    _joined("see ", "iss", "ue 13"),
    _joined("fixes ", "#", "13 for good"),
    _joined("https://github.com/o/r/", "iss", "ues/13"),
    _joined("on main ", "8f2", "0012"),
    _joined("measured at ", "758", "e969 (old)"),
    _joined("the old code (", "0ee", "04ab)"),
    _joined("commit ", "16ba", "4b3 and e70", "ad76"),
    _joined("index ", "64a9", "a07..419", "2ed0 100644"),
    _joined("`", "b62d", "693`"),
    _joined("Measured at main ", "758e", "969 on 2026-11-24"),
])
def test_detector_finds_history(text):
    assert find_history(text), text


@pytest.mark.parametrize("text", [
    "colour #a1b2c3ff and #123456",
    "#define AO_PI 3.14159265358979",
    "#version 330",
    "mask = 0x1f2e3d4c5",
    "sha256 " + "ab12" * 16,
    "byteOffset: 1623360, count 4000000000",
    "enable for this " + _WORD + " without touching saved preferences",
    "@pytest.fixture(scope=\"" + _WORD + "\")",
    "the first render of a " + _WORD,
    "an issue with the 2 cascades",
    "measured 2026-11-24 with ./dev bench",
    "cafe and facade are words (deadbeef is all letters)",
    "an upper-case constant (ABCDEF12) is not a commit",
    "seed (20261107) and 4000000000 triangles",
])
def test_detector_leaves_other_text_alone(text):
    assert not find_history(text), find_history(text)
