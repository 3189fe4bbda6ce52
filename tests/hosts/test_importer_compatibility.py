"""The pre-import checks against Blender's own importers, on a corpus of real mesh files.

Every OBJ, PLY, STL, glTF and GLB file of Debian's ``assimp-testmodels`` package (real
exports, odd encodings, broken and hostile files collected by the assimp project) goes
through ``core/mesh_files.py``'s checks in this process, and through Blender's importer
(the add-on's own importer calls, ``importer_compatibility_driver.py``) on each host (pip
bpy 5.0 and 4.2, whose PLY, STL and OBJ importers are C++, and Debian's Blender 3.4) in
subprocesses that import one file after another; when one dies or hangs, a fresh one
carries on with the next file. The whole sweep takes a few seconds per host. The checks exist to stop what Blender cannot survive, so the
test fails on a file Blender imports with faces that the checks refuse, and on a file the
checks pass that crashes or hangs Blender.
"""

import json
import os
import queue
import re
import subprocess
import threading
import time

import pytest

from csm_engine.core.mesh_files import MeshFileError, check_mesh_file

pytestmark = [pytest.mark.hosts, pytest.mark.slow]

PACKAGE = "assimp-testmodels"
MESH_FILE = re.compile(r"\.(obj|ply|stl|gltf|glb)$", re.IGNORECASE)
DRIVER = os.path.join(os.path.dirname(__file__), "importer_compatibility_driver.py")
# Longest one file may take before the process counts as hung (the largest file of the
# package imports in about a second on a 2-core machine).
FILE_TIMEOUT_S = 60
START_PREFIX = "CSM_START "
RESULT_PREFIX = "CSM_RESULT "


def _corpus():
    try:
        listing = subprocess.run(["dpkg", "-L", PACKAGE], capture_output=True, text=True,
                                 check=False)
    except FileNotFoundError:
        pytest.skip(f"no dpkg here to find Debian's {PACKAGE} package")
    if listing.returncode != 0:
        pytest.skip(f"Debian's {PACKAGE} package is not installed "
                    f"(apt-get install {PACKAGE}; ./dev setup does this)")
    return sorted(path for path in listing.stdout.split()
                  if MESH_FILE.search(path) and os.path.isfile(path))


def _reader(stream, lines):
    for line in stream:
        lines.put(line)
    lines.put(None)


def _import_all(files, command, env, cwd):
    """Blender's outcome for each file: {"faces": n}, {"error": text}, {"crash": code} or
    {"hang": seconds}, importing them in as few processes as the crashes allow."""
    outcomes = {}
    processes = 0
    next_file = 0
    while next_file < len(files):
        batch = files[next_file:]
        processes += 1
        process = subprocess.Popen(command + batch, env=env, cwd=cwd, text=True,
                                   errors="replace", stdin=subprocess.DEVNULL,
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        lines = queue.Queue()
        threading.Thread(target=_reader, args=(process.stdout, lines), daemon=True).start()
        current = None
        deadline = time.monotonic() + FILE_TIMEOUT_S * 2       # Blender's own start-up
        while True:
            try:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                process.kill()
                process.wait()
                outcomes[batch[current or 0]] = {"hang": FILE_TIMEOUT_S}
                next_file += (current or 0) + 1
                break
            if line is None:
                code = process.wait()
                if current is not None and batch[current] not in outcomes:
                    outcomes[batch[current]] = {"crash": code}
                    next_file += current + 1
                elif current is None:
                    pytest.fail(f"the driver died before its first file (exit code {code}): "
                                f"{' '.join(command)}", pytrace=False)
                else:
                    next_file += current + 1
                break
            if START_PREFIX in line:
                current = int(line.split(START_PREFIX, 1)[1].split()[0])
                deadline = time.monotonic() + FILE_TIMEOUT_S
            elif RESULT_PREFIX in line and current is not None:
                outcomes[batch[current]] = json.loads(line.split(RESULT_PREFIX, 1)[1])
    return outcomes, processes


def _checks(path):
    try:
        check_mesh_file(path)
    except MeshFileError as err:
        return str(err)
    return None


@pytest.mark.parametrize("host", ["bpy 5.0", "bpy 4.2", "blender 3.4"])
def test_checks_refuse_only_what_blender_cannot_survive(hosts, tmp_path, host):
    files = _corpus()
    assert files, f"{PACKAGE} is installed but holds no OBJ, PLY, STL, glTF or GLB file"
    started = time.monotonic()
    refusals = {path: _checks(path) for path in files}
    checks_s = time.monotonic() - started
    work = os.path.join(str(tmp_path), "work")
    hosts.copy_package(work)
    command = hosts.script_command(host, DRIVER, work)
    outcomes, processes = _import_all(files, command, hosts.user_dirs_env(str(tmp_path)),
                                      str(tmp_path))
    total_s = time.monotonic() - started

    kinds = ("faces", "no faces", "error", "crash", "hang")
    table = {(refused, kind): 0 for refused in (False, True) for kind in kinds}
    wrongly_refused, let_through = [], []
    for path in files:
        outcome = outcomes[path]
        kind = next(key for key in ("crash", "hang", "error", "faces") if key in outcome)
        if kind == "faces" and outcome["faces"] == 0:
            kind = "no faces"
        refused = refusals[path] is not None
        table[(refused, kind)] += 1
        if refused and kind == "faces":
            wrongly_refused.append(f"{refusals[path]} (Blender read {outcome['faces']} faces)")
        if not refused and kind in ("crash", "hang"):
            what = (f"died (exit code {outcome['crash']})" if kind == "crash"
                    else f"hung for {outcome['hang']} s")
            let_through.append(f"{path}: passed the checks, then Blender's importer {what}")

    print(f"\n{host}, {PACKAGE}: {len(files)} files, checks {checks_s:.2f} s, "
          f"{processes} Blender process(es), {total_s:.1f} s in all")
    print(f"{'checks':>10} " + " ".join(f"{kind:>9}" for kind in kinds))
    for refused in (False, True):
        print(f"{'refused' if refused else 'passed':>10} "
              + " ".join(f"{table[(refused, kind)]:>9}" for kind in kinds))
    assert not wrongly_refused and not let_through, "\n".join(wrongly_refused + let_through)


def test_a_crash_is_recorded_and_the_sweep_goes_on(hosts, tmp_path):
    # A PLY count that is not a number aborts Blender's C++ PLY importer: the process dies
    # on the second file and a fresh one imports the third.
    good, after = tmp_path / "good.obj", tmp_path / "after.obj"
    for path in (good, after):
        path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    crash = tmp_path / "crash.ply"
    crash.write_text("ply\nformat ascii 1.0\nelement vertex three\nproperty float x\n"
                     "end_header\n1 2 3\n")
    files = [str(good), str(crash), str(after)]
    work = os.path.join(str(tmp_path), "work")
    hosts.copy_package(work)
    command = [hosts.bpy50_python(), DRIVER, work]
    outcomes, processes = _import_all(files, command, hosts.user_dirs_env(str(tmp_path)),
                                      str(tmp_path))
    assert "crash" in outcomes[str(crash)], outcomes
    assert outcomes[str(good)] == outcomes[str(after)] == {"faces": 1}
    assert processes == 2
