"""``core`` keeps no state between calls: every module of it imports to constants,
functions, classes and memos of pure functions, and nothing in it writes a module global.

What a view carries from frame to frame lives in ``core.view_state.ShadowViewState``,
which the engine owns; a module-level container would be shared by every view (two
viewports, a viewport and a final render) and by every test in one process.
"""
import ast
import collections
import importlib
import pkgutil
import types
from pathlib import Path

import numpy as np

import csm_engine.core
from csm_engine.core.memo import ArrayMemo, ValueMemo

CORE = Path(csm_engine.core.__file__).parent

# Memos of pure functions, remembered by their arguments' values (core/memo.py): a hit
# returns what a call would, so they never change a result. Listed by where they are
# defined, so a new one is added here on purpose.
MEMOS = {
    ("csm_engine.core.matrices", "inverse_projection"),
    ("csm_engine.core.frame_block", "_window_normal_from_clip_from_world"),
    ("csm_engine.core.frame_block", "_camera_matrices_of_view"),
    ("csm_engine.core.cascades.spaces", "_light_view"),
    ("csm_engine.core.cascades.stabilization", "_view_space_sphere"),
    ("csm_engine.core.cascades.fitting", "_view_slice_corners"),
    ("csm_engine.core.cascades.receivers", "_block_corners"),
    ("csm_engine.core.bsdf_tables", "_tables"),
}

MUTABLE_CONTAINERS = (dict, list, set, bytearray, collections.deque)


def _core_modules():
    modules = [csm_engine.core]
    for info in pkgutil.walk_packages(csm_engine.core.__path__, "csm_engine.core."):
        modules.append(importlib.import_module(info.name))
    return modules


def _mutable_parts(value, where):
    """Where ``value`` (a module-level constant) holds something that can change."""
    if isinstance(value, MUTABLE_CONTAINERS):
        return [f"{where}: a {type(value).__name__}"]
    if isinstance(value, np.ndarray):
        return [f"{where}: a writeable array"] if value.flags.writeable else []
    if isinstance(value, (tuple, frozenset)):
        return [bad for index, item in enumerate(value)
                for bad in _mutable_parts(item, f"{where}[{index}]")]
    if isinstance(value, types.MappingProxyType):
        return [bad for key, item in value.items()
                for bad in _mutable_parts(item, f"{where}[{key!r}]")]
    return []


def test_every_core_file_is_seen():
    names = {module.__name__ for module in _core_modules()}
    files = {".".join(("csm_engine", "core") + path.relative_to(CORE).with_suffix("").parts)
             .removesuffix(".__init__") for path in CORE.rglob("*.py")}
    assert files <= names, files - names
    assert {"csm_engine.core.shadow_plan", "csm_engine.core.cascades.fitting",
            "csm_engine.core.view_state"} <= names


def test_no_global_statements_in_core():
    found = []
    for path in sorted(CORE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Global, ast.Nonlocal)):
                found.append(f"{path.relative_to(CORE)}:{node.lineno}: "
                             f"{type(node).__name__.lower()} {', '.join(node.names)}")
    assert not found, found


def test_no_mutable_module_level_values_in_core():
    found = []
    for module in _core_modules():
        for name, value in vars(module).items():
            if name.startswith("__") or isinstance(value, (types.ModuleType, type,
                                                           types.FunctionType)):
                continue
            found += _mutable_parts(value, f"{module.__name__}.{name}")
    assert not found, found


def test_the_only_module_level_memos_are_the_listed_memos_of_pure_functions():
    where = collections.defaultdict(set)
    for module in _core_modules():
        for name, value in vars(module).items():
            if isinstance(value, (ArrayMemo, ValueMemo)):
                where[id(value)].add((module.__name__, name))
    unlisted = [sorted(places) for places in where.values() if not places & MEMOS]
    assert not unlisted, f"memos not in MEMOS: {unlisted}"
    missing = MEMOS - set().union(*where.values())
    assert not missing, f"listed memos that no longer exist: {missing}"


def test_memo_results_cannot_be_changed_by_a_caller():
    memo = ValueMemo(lambda a, b: (np.full(2, a), np.full(2, b)), 4,
                     key=lambda a, b: (a, b))
    first = memo(1.0, 2.0)
    assert all(not part.flags.writeable for part in first)
    np.testing.assert_array_equal(memo(1.0, 2.0)[1], [2.0, 2.0])
    for size in range(10):                # forgets when full, and still answers right
        np.testing.assert_array_equal(memo(float(size), 0.0)[0], [size, size])
