"""Memos of pure functions, remembered by the values of their arguments.

Owns ``ArrayMemo`` (a function of one float64 array, keyed by the array's bytes) and
``ValueMemo`` (a function of any arguments, keyed by a hashable value its ``key`` function
builds from them). A hit returns exactly what calling the function would return, so a memo
changes how long a frame takes, never what it draws; both hold at most ``size`` results
and forget them all when full. Results are made read-only, so a caller cannot change what
the next caller gets.

What a view remembers from one frame to the next (frozen cascades, hysteresis, caches
keyed by object identity) is not a memo: it lives in ``view_state.ShadowViewState``.
These two classes are the only module-level objects in ``core`` that hold anything
mutable (tests/unit/test_core_has_no_module_state.py checks it). numpy only.
"""

import numpy as np


def _read_only(result):
    for part in (result if isinstance(result, tuple) else (result,)):
        if isinstance(part, np.ndarray):
            part.setflags(write=False)
    return result


class ArrayMemo:
    """A pure function of one float64 array, remembered by the array's bytes (at most
    ``size`` results; all forgotten when full). Results are made read-only."""

    def __init__(self, function, size):
        self.function, self.size, self._held = function, size, {}

    def __call__(self, array):
        array = np.ascontiguousarray(array, dtype=np.float64)
        key = array.tobytes()
        result = self._held.get(key)
        if result is None:
            if len(self._held) >= self.size:
                self._held.clear()
            result = _read_only(self.function(array))
            self._held[key] = result
        return result


class ValueMemo:
    """A pure function remembered by ``key(*args)``: a hashable value that must stand for
    every argument value the result depends on (array arguments by their bytes, never by
    identity). At most ``size`` results; all forgotten when full. Results (arrays, or
    arrays in a tuple) are made read-only."""

    def __init__(self, function, size, key):
        self.function, self.size, self.key, self._held = function, size, key, {}

    def __call__(self, *args):
        key = self.key(*args)
        result = self._held.get(key)
        if result is None:
            if len(self._held) >= self.size:
                self._held.clear()
            result = _read_only(self.function(*args))
            self._held[key] = result
        return result
