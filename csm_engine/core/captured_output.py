"""Capture what native code prints, at the file-descriptor level.

Owns ``CapturedOutput``: a context manager that points file descriptors 1 and 2 (stdout
and stderr) at a temporary file for its duration and keeps what was written there as
``.text``. Python's ``print`` and C code writing to the same descriptors (Blender's
importers, a GL driver's compiler log) are both caught, which ``contextlib.redirect_*``
cannot do. ``sys.stdout``/``sys.stderr`` are pointed at the same file too, in case they
were replaced by objects that do not write to the descriptors (a test runner's), and C's
own stdio buffers are flushed on the way out, so output that libc still holds is not
printed later, after the descriptors are back. Plain standard library: no Blender needed.

NOTE: a process that dies inside the block (a C++ abort) loses what was captured; callers
that can crash a host must validate their input first.
"""

import ctypes
import io
import os
import sys
import tempfile


class CapturedOutput:
    """``with CapturedOutput() as captured: ...`` then read ``captured.text``."""

    def __init__(self):
        self.text = ""
        self._file = None
        self._saved = None

    def __enter__(self):
        _flush()
        self._file = tempfile.TemporaryFile(mode="w+b")
        saved = []
        try:
            for fd in (1, 2):
                saved.append(os.dup(fd))
            for fd in (1, 2):
                os.dup2(self._file.fileno(), fd)
        except OSError:
            # A descriptor that is closed or cannot be duplicated: capture nothing rather
            # than fail the caller's work.
            for fd, copy in zip((1, 2), saved):
                os.dup2(copy, fd)
                os.close(copy)
            saved = None
        self._saved = saved
        self._streams = (sys.stdout, sys.stderr)
        if saved is not None:
            text = io.TextIOWrapper(os.fdopen(os.dup(self._file.fileno()), "wb"),
                                    encoding="utf-8", errors="replace", line_buffering=True)
            self._text_stream = text
            sys.stdout = sys.stderr = text
        return self

    def __exit__(self, *exc):
        _flush()
        _flush_c_stdio()
        if self._saved is not None:
            sys.stdout, sys.stderr = self._streams
            self._text_stream.close()
            for fd, copy in zip((1, 2), self._saved):
                os.dup2(copy, fd)
                os.close(copy)
            self._saved = None
        self._file.seek(0)
        self.text = self._file.read().decode("utf-8", "replace")
        self._file.close()
        self._file = None
        return False


def _flush_c_stdio():
    """fflush(NULL): C code's printf output still buffered in libc goes out now, into the
    captured file, rather than after the descriptors are restored."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):
        pass


def _flush():
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            pass
