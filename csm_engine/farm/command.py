"""``python -m csm_engine FILE.blend --frames 1-240 --output renders/f_####.png --workers N``:
the farm's command line, on the machine that asks for the frames.

Owns the arguments and their checks (every mistake is one line and an exit code, before
any worker starts), the Dask cluster (``--workers N``: a local cluster of N worker
processes, one thread each, every one with its own bpy; ``--scheduler ADDRESS``: an
existing cluster), one task per frame handed out in frame order, the progress lines, and
the exit code, which is 0 only when every frame's file is there at the end. A worker that
dies takes its frame with it; Dask's scheduler hands that frame to another worker (and a
local cluster's nanny starts a new process). Frames whose file exists are not sent at all
unless ``--overwrite``.

Dask is imported only here, only once the arguments are good: without it the command
says in one line how to install it. The coordinator never imports bpy: the workers render.
"""

import argparse
import dataclasses
import importlib.util
import os
import sys
import time
import types
import uuid

from ..blender.cli import (EXIT_NO_BLENDER, EXIT_RENDER, EXIT_SCENE, CLIError,
                           apply_override, shell_path)
from . import frames as frame_rules
from . import worker
from .worker import FAILED, PRESENT, WRITTEN, FarmJob

EXIT_NO_DASK = 7          # this Python has no dask.distributed
INSTALL_HINT = "pip install csm_engine[farm]"
# The first bytes of a .blend: plain, gzip-compressed (Blender before 3.0) or
# zstd-compressed (3.0 and later).
BLEND_MAGIC = (b"BLENDER", b"\x1f\x8b", b"\x28\xb5\x2f\xfd")
MAX_LOCAL_WORKERS = 256


# Options of either command that take a value: their value is not the scene.
_VALUE_OPTIONS = {"--frames", "--output", "--workers", "--scheduler", "--set",
                  "--resolution", "--allow-folder"}


def is_farm_command(argv):
    """Whether ``argv`` asks for the farm: its first argument that is neither an option
    nor an option's value is a .blend file (the one-scene command takes a .json)."""
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg == "--":
            return False
        elif arg.startswith("-"):
            skip = arg in _VALUE_OPTIONS
        else:
            return arg.lower().endswith(".blend")
    return False


def build_parser(prog):
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Render a .blend's animation frames with CSM on a Dask cluster: each "
                    "worker opens the file once and renders its share of the frames.")
    parser.add_argument("blend", help="the .blend file (its active scene is rendered)")
    parser.add_argument("--frames", metavar="A-B",
                        help="frames to render: 1-240, 7, or a list like 1-10,20,30-40 "
                             "(default: the file's Frame Start to End)")
    parser.add_argument("--output", required=True, metavar="PATTERN",
                        help="where frames go, # marking the frame number: "
                             "renders/f_####.png writes renders/f_0001.png, ...")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="start a local cluster of N worker processes (default 1); 0 "
                            "renders in this process, without Dask")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use an existing Dask cluster, e.g. tcp://10.0.0.5:8786")
    parser.add_argument("--overwrite", action="store_true",
                        help="render frames whose file exists already (default: keep them)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="SETTING=VALUE", help="override a CSM setting (repeatable)")
    return parser


def check_blend(text):
    """The .blend's absolute path, or CLIError saying what is wrong with it."""
    path = os.path.abspath(os.path.expanduser(text))
    if not os.path.exists(path):
        raise CLIError(f"{text}: no such file", EXIT_SCENE)
    if not os.path.isfile(path):
        raise CLIError(f"{text}: is a folder, not a .blend file", EXIT_SCENE)
    try:
        with open(path, "rb") as handle:
            head = handle.read(8)
    except OSError as error:
        raise CLIError(f"{text}: cannot read it ({error.strerror})", EXIT_SCENE) from None
    if not head.startswith(BLEND_MAGIC):
        raise CLIError(f"{text}: not a .blend file (it does not start as one)", EXIT_SCENE)
    return path


def check_overrides(overrides):
    """Each ``--set`` checked against the settings model, as a render would check it."""
    if not overrides:
        return ()
    from ..core import settings_model
    values = types.SimpleNamespace(**{s.identifier: s.default for s in settings_model.SETTINGS})
    for override in overrides:
        apply_override(values, override)
    return tuple(overrides)


def import_dask():
    try:
        import distributed
    except ImportError:
        raise CLIError(f"{sys.executable} has no dask.distributed, which the farm runs on: "
                       f"{INSTALL_HINT} (or pip install distributed)", EXIT_NO_DASK) from None
    return distributed


def start_cluster(distributed, args):
    """(client, cluster or None): a local cluster of ``args.workers`` processes, or a
    client of the cluster at ``args.scheduler``."""
    if args.scheduler:
        try:
            client = distributed.Client(args.scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as error:
            reason = " ".join(str(error).split()) or type(error).__name__
            raise CLIError(f"--scheduler: cannot reach {args.scheduler}: {reason}") from None
        return client, None
    # One thread per worker: bpy is one Blender session per process, and llvmpipe spreads
    # each frame over the machine's cores by itself. No memory limit: a Blender session's
    # size is the scene's, and a worker restarted for it would lose its warm caches.
    cluster = distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1,
                                       processes=True, memory_limit=0,
                                       dashboard_address=None, scheduler_port=0)
    return distributed.Client(cluster), cluster


def close(client, cluster):
    """Closes the client and, for a local cluster, its workers and scheduler, without the
    traceback Dask logs when a worker's heartbeat is in flight as the scheduler goes: the
    workers stop their heartbeats and drop that one message before anything closes."""
    if cluster is not None:
        try:
            client.run(worker.stop_heartbeat, on_error="ignore")
        except Exception:       # a broken cluster still closes below
            pass
    client.close()
    if cluster is not None:
        cluster.close()


def say(text):
    print(f"csm: {text}", flush=True)


def run(argv, prog):
    args = build_parser(prog).parse_args(argv)
    blend = check_blend(args.blend)
    try:
        wanted = frame_rules.parse_frames(args.frames) if args.frames is not None else None
        pattern = frame_rules.check_pattern(args.output)
    except frame_rules.FrameSpecError as error:
        raise CLIError(str(error)) from None
    args.workers = 1 if args.workers is None else args.workers
    if not args.scheduler and not 0 <= args.workers <= MAX_LOCAL_WORKERS:
        raise CLIError(f"--workers: {args.workers} is outside 0..{MAX_LOCAL_WORKERS}")
    if args.scheduler and "://" not in args.scheduler:
        raise CLIError(f"--scheduler: '{args.scheduler}' is not an address like "
                       "tcp://HOST:8786")
    overrides = check_overrides(args.overrides)
    if wanted is not None:
        todo, _ = frame_rules.frames_to_render(pattern, wanted, args.overwrite)
        if not todo:
            say(f"all {len(wanted)} frames are there already "
                f"({shell_path(frame_rules.frame_path(pattern, wanted[0]))} ...); "
                "--overwrite renders them again")
            return 0
    distributed = import_dask() if args.scheduler or args.workers else None
    if not args.scheduler and importlib.util.find_spec("bpy") is None:
        where = "this process renders" if not args.workers else \
            "the local workers run this Python"
        raise CLIError(f"{sys.executable} has no bpy, and {where}: pip install bpy==5.0.1 "
                       "(Python 3.11)" + ("" if not args.workers else ", or give --scheduler"),
                       EXIT_NO_BLENDER)
    started = time.perf_counter()
    job = FarmJob(blend, pattern, args.overwrite, overrides, wanted[0] if wanted else 0)
    try:
        if distributed is None:
            return _render_all(InProcess(), job, wanted, "in this process", started)
        client, cluster = start_cluster(distributed, args)
        try:
            where = "on " + (args.scheduler or
                             f"{args.workers} local worker{'s' * (args.workers > 1)}")
            return _render_all(OnCluster(distributed, client), job, wanted, where, started)
        finally:
            close(client, cluster)
    except KeyboardInterrupt:
        print("csm: interrupted; the frames written so far are complete, and the same "
              "command renders the rest", file=sys.stderr)
        return 130


class InProcess:
    """``--workers 0``: this process is the one worker (no Dask; a farm that runs one
    command per chunk of frames, such as an Open Job Description step, uses it)."""

    def scene_frames(self, job):
        return worker.scene_frames(job)

    def reports(self, job, todo):
        for frame in todo:
            yield frame, worker.render_frame(job, frame,
                                             frame_rules.frame_path(job.pattern, frame))


class OnCluster:
    """One Dask task per frame, handed out in frame order."""

    def __init__(self, distributed, client):
        self.distributed = distributed
        self.client = client

    def scene_frames(self, job):
        # The worker that reads the range keeps the file open for its frames.
        return self.client.submit(worker.scene_frames, job, pure=False).result()

    def reports(self, job, todo):
        run_id = uuid.uuid4().hex[:8]
        futures = {}
        for index, frame in enumerate(todo):
            # Higher priority runs first: frames go out in order, so each worker renders
            # an increasing sequence and its caches follow the animation.
            future = self.client.submit(worker.render_frame, job, frame,
                                        frame_rules.frame_path(job.pattern, frame),
                                        key=f"csm-frame-{frame}-{run_id}", pure=False,
                                        priority=len(todo) - index)
            futures[future] = frame
        for future in self.distributed.as_completed(list(futures)):
            frame = futures[future]
            try:
                report = future.result()
            except Exception as error:   # a worker lost too often, or a bug in a worker
                reason = " ".join(str(error).split()) or type(error).__name__
                report = worker.FrameReport(
                    frame, frame_rules.frame_path(job.pattern, frame), FAILED,
                    message=f"frame {frame}: {type(error).__name__}: {reason}")
            yield frame, report


def _render_all(runner, job, wanted, where, started):
    pattern = job.pattern
    if wanted is None:
        # The file's own range, as blender -a renders it.
        wanted = runner.scene_frames(job)
        if not wanted:
            raise CLIError(f"{shell_path(job.blend_path)}: its frame range is empty")
        job = dataclasses.replace(job, first_frame=wanted[0])
    todo, present = frame_rules.frames_to_render(pattern, wanted, job.overwrite)
    kept = f", {len(present)} there already" if present else ""
    say(f"rendering {len(todo)} of {len(wanted)} frames of {shell_path(job.blend_path)} "
        f"{where}{kept}")
    failures = 0
    # A file no worker can open fails every frame the same way: said once, not per frame.
    said = set()
    for done, (frame, report) in enumerate(runner.reports(job, todo), start=1):
        _print_worker_output(report.output)
        path = shell_path(report.path)
        if report.status == WRITTEN:
            opened = (f", opened the file in {report.open_seconds:.1f} s"
                      if report.open_seconds else "")
            say(f"[{done}/{len(todo)}] wrote {path} in {report.render_seconds:.2f} s "
                f"(worker {report.worker}{opened})")
        elif report.status == PRESENT:
            say(f"[{done}/{len(todo)}] {path} is there already")
        else:
            failures += 1
            if report.message not in said:
                said.add(report.message)
                print(f"csm: error: {report.message}", file=sys.stderr, flush=True)
    missing = [frame for frame in wanted
               if not frame_rules.frame_done(frame_rules.frame_path(pattern, frame))]
    if missing:
        listed = ", ".join(str(f) for f in missing[:10]) + (" ..." if len(missing) > 10 else "")
        print(f"csm: error: {len(missing)} of {len(wanted)} frames were not written "
              f"({listed}); the same command renders only those", file=sys.stderr)
        return EXIT_RENDER
    say(f"all {len(wanted)} frames are there ({len(todo) - failures} rendered in "
        f"{time.perf_counter() - started:.1f} s)")
    return 0


def _print_worker_output(text):
    """What a worker's Blender printed that tells the user something (warnings), without
    the start-up and progress noise the one-scene command also hides."""
    from ..blender.cli import pass_through
    if text:
        pass_through(text)


def main(argv, prog="python -m csm_engine"):
    try:
        return run(argv, prog)
    except CLIError as error:
        print(f"csm: error: {error}", file=sys.stderr)
        return error.code
