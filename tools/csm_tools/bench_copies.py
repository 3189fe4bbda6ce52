"""Many copies of one mesh: import + first render time and peak memory, CSM beside EEVEE.

Writes course scene files of N objects referencing one small mesh file (a box on a
ground, in a square grid, turned and scaled per object, every seventh mirrored, seen
from the importer's default camera) or
D distinct files x N copies, and renders each in a fresh process from the command line
(``python -m csm_engine scene.json out.png``) under ``/usr/bin/time -v`` (wall time and
peak resident memory), and the same import rendered by EEVEE. Results go to
docs/benchmarks.md ("Many copies of one mesh").

    ./dev bench-copies [--sizes 1000,10000,100000] [--distinct 10x10000] [--folder DIR]
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RESOLUTION = "320x180"


def write_box_obj(path, half=0.4, height=1.0):
    """A box (12 triangles), its base on y = 0."""
    corners = [(x, y, z) for x in (-half, half) for y in (0.0, height) for z in (-half, half)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    with open(path, "w") as stream:
        stream.writelines(f"v {x} {y} {z}\n" for x, y, z in corners)
        stream.writelines("f " + " ".join(map(str, face)) + "\n" for face in faces)
    return path


def write_ground_obj(path, half):
    with open(path, "w") as stream:
        stream.write(f"v {-half} 0 {-half}\nv {half} 0 {-half}\nv {half} 0 {half}\n"
                     f"v {-half} 0 {half}\nf 1 4 3 2\n")
    return path


def write_scene(folder, copies, distinct=1, seed=0):
    """A scene of ``copies`` objects per mesh file, ``distinct`` files, in one square grid
    (2 m apart) on a ground; returns its path."""
    rng = np.random.default_rng(seed)
    os.makedirs(folder, exist_ok=True)
    meshes = [write_box_obj(os.path.join(folder, f"box{d}.obj"), 0.3 + 0.05 * d,
                            0.6 + 0.15 * d) for d in range(distinct)]
    total = copies * distinct
    side = int(np.ceil(np.sqrt(total)))
    spacing = 2.0
    half = side * spacing / 2.0
    write_ground_obj(os.path.join(folder, "ground.obj"), half + 2.0)
    cells = np.arange(total)
    x = (cells % side) * spacing - half + spacing / 2
    z = (cells // side) * spacing - half + spacing / 2
    turn = rng.uniform(0.0, 360.0, total)
    grow = rng.uniform(0.7, 1.4, total)
    order = rng.permutation(total)      # each file's copies spread over the whole grid
    objects = [{"mesh": "ground.obj"}]
    for i in range(total):
        cell = order[i]
        mirror = -1.0 if i % 7 == 3 else 1.0
        objects.append({
            "mesh": os.path.basename(meshes[i % distinct]),
            "translate": {"x": float(x[cell]), "y": 0.0, "z": float(z[cell])},
            "rotate": {"x": 0.0, "y": float(turn[i]), "z": 0.0},
            "scale": {"x": mirror, "y": float(grow[i]), "z": 1.0}})
    # No camera: the importer's default view of the whole scene (a raised diagonal).
    scene = {
        "objects": objects, "lights": [],
        "directional_light": {"direction": {"x": 0.4, "y": -0.8, "z": -0.3},
                              "color": {"x": 1.0, "y": 1.0, "z": 1.0}}}
    path = os.path.join(folder, f"copies_{distinct}x{copies}.json")
    with open(path, "w") as stream:
        json.dump(scene, stream)
    return path


_EEVEE_RENDER = """
import sys, time
from csm_engine.blender import cli
import bpy
scene = cli.open_scene(sys.argv[-2], resolution=(320, 180))
scene.render.engine = {engine!r}
if hasattr(scene, "eevee"):
    scene.eevee.taa_render_samples = 1
scene.render.filepath = sys.argv[-1]
bpy.ops.render.render(write_still=True)
"""


def _eevee_engine():
    import bpy
    items = bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items.keys()
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"


def timed(command, env=None):
    """Run ``command`` under /usr/bin/time -v: (wall seconds, peak RSS in MB, output).
    Without /usr/bin/time, the child's own resource usage (``os.wait4``) gives the peak."""
    if not os.path.exists("/usr/bin/time"):
        return _timed_by_wait4(command, env)
    start = time.perf_counter()
    done = subprocess.run(["/usr/bin/time", "-v", *command], capture_output=True,
                          text=True, env=env)
    wall = time.perf_counter() - start
    if done.returncode:
        raise RuntimeError(f"{command} failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    peak = re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr)
    return wall, int(peak.group(1)) / 1024.0 if peak else float("nan"), done.stdout


def _timed_by_wait4(command, env=None):
    start = time.perf_counter()
    with tempfile.TemporaryFile("w+") as out:
        child = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, text=True,
                                 env=env)
        _pid, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - start
        out.seek(0)
        text = out.read()
    if child.returncode:
        raise RuntimeError(f"{command} failed:\n{text[-3000:]}")
    return wall, usage.ru_maxrss / 1024.0, text


def run(sizes, distinct, folder, with_eevee=True):
    env = dict(os.environ, PYTHONPATH=ROOT)
    rows = []
    cases = [(1, n) for n in sizes] + list(distinct)
    for files, copies in cases:
        scene = write_scene(os.path.join(folder, f"{files}x{copies}"), copies, files)
        out = os.path.join(folder, f"csm_{files}x{copies}.png")
        wall, peak, _ = timed([sys.executable, "-m", "csm_engine", "--resolution",
                               RESOLUTION, scene, out], env)
        row = {"files": files, "copies": copies, "csm_s": wall, "csm_mb": peak,
               "png": out}
        if with_eevee:
            script = os.path.join(folder, "eevee_render.py")
            with open(script, "w") as stream:
                stream.write(_EEVEE_RENDER.format(engine=_eevee_engine()))
            eevee_png = os.path.join(folder, f"eevee_{files}x{copies}.png")
            row["eevee_s"], row["eevee_mb"], _ = timed(
                [sys.executable, script, scene, eevee_png], env)
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(prog="./dev bench-copies",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1000,10000,100000",
                        help="copies of one file per case, comma-separated")
    parser.add_argument("--distinct", default="10x10000",
                        help="files x copies cases, comma-separated ('' for none)")
    parser.add_argument("--no-eevee", action="store_true")
    parser.add_argument("--folder", default=None,
                        help="where the scenes are written (default: a new temporary folder)")
    args = parser.parse_args(argv)
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s]
        distinct = [tuple(int(v) for v in case.split("x")) for case in
                    args.distinct.split(",") if case]
    except ValueError:
        parser.error(f"--sizes {args.sizes!r} / --distinct {args.distinct!r}: whole numbers "
                     "like 1000,10000 and 10x10000")
    if any(size < 1 for size in sizes) or any(len(case) != 2 or min(case) < 1
                                               for case in distinct):
        parser.error(f"--sizes {args.sizes!r} / --distinct {args.distinct!r}: at least 1 "
                     "copy, and FILESxCOPIES for --distinct")
    folder = args.folder or tempfile.mkdtemp(prefix="csm_copies_")
    run(sizes, distinct, folder, not args.no_eevee)


if __name__ == "__main__":
    main()
