"""A/B of two GLSL folders on one of the benchmark's camera animations, in one process.

Owns ``./dev shader-ab``: both folders' programs are compiled (each a ``ShaderLibrary`` of
its own), then every frame of the animation (``bench.camera_flight``) is rendered once with
each, in alternating order, profiled per pass. The two share the machine's state at every
frame, so a few percent between them hold even where a run as a whole drifts by more.
Prints the median milliseconds per pass of A and of B, and B / A.

    ./dev shader-ab SCENE FOLDER_A FOLDER_B [--frames 10] [--resolution 1280x720]

A folder is a copy of ``shaders/`` (with ``lighting_frag.glsl``), edited to try a change.
"""

import argparse
import os
import statistics

from csm_engine.blender.cli import (CLIError, keep_freed_memory, parse_resolution,
                                    run_reporting_errors)

from . import bench

PROG = "./dev shader-ab"
STEPS = ("shadow", "gbuffer", "depth_range", "ao", "lighting", "fxaa", "wall")


def build_parser(prog=PROG):
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", choices=bench.SCENES, help="the benchmark's scene")
    parser.add_argument("folder_a", help="GLSL folder A (a copy of shaders/)")
    parser.add_argument("folder_b", help="GLSL folder B")
    parser.add_argument("--frames", type=int, default=10,
                        help="animation frames, each rendered with A and B (default 10)")
    parser.add_argument("--resolution", default="1280x720", help="image size (WxH)")
    return parser


def _shader_folder(path, option):
    from csm_engine.core.paths import SHADER_MARKER
    if not os.path.isfile(os.path.join(path, SHADER_MARKER)):
        raise CLIError(f"{option}: '{path}' is not a GLSL folder (no {SHADER_MARKER})")
    return os.path.abspath(path)


def run(argv, prog=PROG):
    args = build_parser(prog).parse_args(argv)
    width, height = parse_resolution(args.resolution)
    if args.frames < 1:
        raise CLIError(f"--frames: needs at least 1, got {args.frames}")
    folders = {"A": _shader_folder(args.folder_a, "FOLDER_A"),
               "B": _shader_folder(args.folder_b, "FOLDER_B")}
    from csm_engine.render import shaders
    scene = bench.build_scene(args.scene, False, width, height)
    scene.render.engine = "CSM"
    default = shaders.LIBRARY
    libraries = {}
    steps = {label: [] for label in folders}
    try:
        for label, folder in folders.items():
            library = shaders.ShaderLibrary(directory=folder)
            library.host_defines = default.host_defines
            libraries[label] = shaders.LIBRARY = library
            bench.render_once(scene)        # compiles its programs, fills the caches
        with bench.camera_flight(scene, args.frames) as numbers:
            for index, frame in enumerate(numbers):
                scene.frame_set(frame)
                for label in ("A", "B") if index % 2 == 0 else ("B", "A"):
                    shaders.LIBRARY = libraries[label]
                    steps[label].append(bench.step_seconds(
                        bench.render_once(scene, profile=True)))
    finally:
        shaders.LIBRARY = default
    print(f"{args.scene}, {width}x{height}, {args.frames} frames each; median ms")
    print(f"{'pass':<12} {'A':>8} {'B':>8} {'B / A':>7}")
    for step in STEPS:
        a, b = (1000 * statistics.median(f[step] for f in steps[label]) for label in "AB")
        print(f"{step:<12} {a:8.1f} {b:8.1f} {b / a if a > 0 else float('nan'):7.3f}")
    return 0


def main(argv=None, prog=PROG):
    keep_freed_memory()
    return run_reporting_errors(run, argv, prog, "shader A/B")


if __name__ == "__main__":
    from csm_engine.blender.compat import exit_process
    exit_process(main())
