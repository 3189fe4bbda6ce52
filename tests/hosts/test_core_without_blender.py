"""``csm_engine/core`` is pure: its unit tests pass on Debian's own Python 3, which has
numpy but no Blender at all (not even an importable ``bpy`` to refuse)."""
import os
import re
import subprocess

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.hosts
SYSTEM_PYTHON = "/usr/bin/python3"


def test_unit_tests_pass_on_a_python_without_blender():
    if not os.access(SYSTEM_PYTHON, os.X_OK):
        pytest.fail(f"{SYSTEM_PYTHON} not found: apt-get install python3 python3-numpy "
                    "python3-pytest python3-hypothesis (./dev setup does)", pytrace=False)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import bpy"], capture_output=True,
                           text=True, env=env, cwd=REPO, timeout=60)
    assert probe.returncode != 0 and "No module named 'bpy'" in probe.stderr, probe.stderr
    run = subprocess.run([SYSTEM_PYTHON, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          os.path.join("tests", "unit")], capture_output=True, text=True,
                         env=env, cwd=REPO, timeout=900, stdin=subprocess.DEVNULL)
    summary = run.stdout.strip().splitlines()[-1] if run.stdout.strip() else run.stderr
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    passed = re.search(r"(\d+) passed", summary)
    assert passed and int(passed.group(1)) >= 300, summary
    assert not re.search(r"\d+ (failed|error|skipped)", summary), summary
