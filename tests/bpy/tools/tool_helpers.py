"""Running a measuring tool the way ``./dev`` does: ``python -m csm_tools.<module>`` with the
repository root and ``tools/`` on PYTHONPATH, but on this test session's interpreter, so the
tool runs on the same pip bpy as the tests (5.0 in .venv, 4.2 in .venv-bpy42)."""
import os
import subprocess
import sys

from tests.conftest import REPO, TOOLS


def run_module(module, *args, cwd, timeout, **env):
    """Run ``csm_tools.<module>`` with ``args`` in a subprocess; ``env`` overrides the
    environment (None removes a variable). Returns the CompletedProcess (text output)."""
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join([REPO, TOOLS]))
    for name, value in env.items():
        if value is None:
            environment.pop(name, None)
        else:
            environment[name] = value
    return subprocess.run([sys.executable, "-m", f"csm_tools.{module}", *map(str, args)],
                          cwd=str(cwd), env=environment, capture_output=True, text=True,
                          timeout=timeout)
