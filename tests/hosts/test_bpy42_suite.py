"""The window-less suite on pip bpy 4.2 LTS as well as 5.0.

``tests/bpy`` (registration, settings and their tooltips, operators, keymap entries, undo,
scene import, shader errors, renders checked by pixels, the ground-truth and report tools)
runs in-process on pip bpy 5.0 with the rest of ``./dev test``; here the same files run
again in a subprocess of the bpy 4.2 interpreter, the oldest Blender the extension
supports. Not the tests marked ``benchmark`` (the speed-measuring tools): speed is
measured and published on the main host only, and they would add about a third to the
time this takes.

What counts is the suite's own list of tests: pytest collects ``tests/bpy`` on pip bpy 5.0,
and every one of those tests must have run on 4.2 (none missing, none extra) and passed,
failed as expected (a strict ``xfail``, the same on every host), or been skipped with a
reason that names 4.2. No failures, no errors. A failure shows pytest's own report from 4.2.
"""

import os
import re
import subprocess
import xml.etree.ElementTree as ElementTree

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.hosts
SUITE_TIMEOUT_S = 900
COLLECT_TIMEOUT_S = 300
SUITE = os.path.join("tests", "bpy")
SELECTION = ("-m", "not benchmark")


def _environment():
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def collected_on_bpy_5_0(hosts):
    """The node ids of ``tests/bpy`` as pytest collects them on pip bpy 5.0."""
    proc = subprocess.run([hosts.bpy50_python(), "-m", "pytest", "--collect-only", "-q",
                           "-p", "no:cacheprovider", "-p", "no:warnings", *SELECTION,
                           SUITE],
                          cwd=REPO, env=_environment(), capture_output=True, text=True,
                          timeout=COLLECT_TIMEOUT_S, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, \
        f"collecting tests/bpy on pip bpy 5.0 failed:\n{proc.stdout[-4000:]}{proc.stderr[-2000:]}"
    ids = [line.strip() for line in proc.stdout.splitlines()
           if line.startswith(SUITE.replace(os.sep, "/") + "/") and "::" in line]
    summary = re.search(r"(\d+)(?:/\d+)? tests? collected", proc.stdout)
    assert summary and int(summary.group(1)) == len(ids) > 0, proc.stdout[-2000:]
    return ids


def junit_name(node_id):
    """A pytest node id as JUnit XML names the test case: (classname, name)."""
    path, *parts = node_id.split("::")
    module = path[:-len(".py")].replace("/", ".").replace(os.sep, ".")
    return ".".join([module, *parts[:-1]]), parts[-1]


def outcomes(junit_xml):
    """{(classname, name): (outcome, message)} from pytest's JUnit XML report; outcome is
    "passed", "failed", "error", "skipped" or "xfailed"."""
    result = {}
    for case in ElementTree.parse(junit_xml).getroot().iter("testcase"):
        key = (case.get("classname"), case.get("name"))
        outcome, message = "passed", ""
        for child in case:
            if child.tag in ("failure", "error"):
                outcome, message = ("failed" if child.tag == "failure" else "error",
                                    child.get("message", ""))
                break
            if child.tag == "skipped":
                outcome = "xfailed" if child.get("type") == "pytest.xfail" else "skipped"
                message = child.get("message", "")
        result[key] = outcome, message
    return result


def test_window_less_suite_passes_on_pip_bpy_4_2(hosts, tmp_path):
    python = hosts.bpy42_python()
    version = subprocess.run([python, "-c", "import bpy; print(bpy.app.version_string)"],
                             capture_output=True, text=True, timeout=120,
                             stdin=subprocess.DEVNULL)
    assert version.stdout.strip().startswith("4.2"), version.stdout + version.stderr[-2000:]
    expected = [junit_name(node_id) for node_id in collected_on_bpy_5_0(hosts)]
    junit_xml = os.path.join(str(tmp_path), "bpy42.xml")
    proc = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           f"--junitxml={junit_xml}", *SELECTION, SUITE],
                          cwd=REPO, env=_environment(), capture_output=True, text=True,
                          timeout=SUITE_TIMEOUT_S, stdin=subprocess.DEVNULL)
    report = proc.stdout[-6000:] + proc.stderr[-2000:]
    assert proc.returncode == 0, f"tests/bpy failed on pip bpy 4.2:\n{report}"
    assert os.path.isfile(junit_xml), f"pytest on 4.2 wrote no JUnit report:\n{report}"
    ran = outcomes(junit_xml)
    missing = sorted(set(expected) - set(ran))
    extra = sorted(set(ran) - set(expected))
    assert not missing, f"{len(missing)} of the suite's tests did not run on 4.2: {missing[:20]}"
    assert not extra, f"4.2 ran tests that 5.0 does not collect: {extra[:20]}"
    bad = {key: value for key, value in ran.items()
           if value[0] in ("failed", "error")
           or (value[0] == "skipped" and "4.2" not in value[1])}
    assert not bad, f"on pip bpy 4.2, not passed: {bad}\n{report}"
    counts = {}
    for outcome, _message in ran.values():
        counts[outcome] = counts.get(outcome, 0) + 1
    print(f"tests/bpy on pip bpy 4.2: {len(expected)} collected on 5.0, {counts}")
    assert counts.get("passed", 0) + counts.get("skipped", 0) + counts.get("xfailed", 0) == \
        len(expected)
