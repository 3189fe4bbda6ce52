"""What runs inside each farm worker process: one Blender session per process that opens
the job's .blend once and renders the frames the scheduler hands it, in the order it gets
them, with CSM, so meshes, shaders and render targets stay warm from frame to frame.

Owns ``FarmJob`` (what every frame of one run shares), ``FrameReport`` (what one frame
task sends back), the per-process ``WorkerSession`` and the functions Dask calls by
reference: the tasks ``scene_frames`` (the file's own frame range) and ``render_frame``, and
``stop_heartbeat``, which the farm runs on its local workers before it closes them. No Dask
import here: a task is a plain function of plain data. bpy is imported when the first task
runs, in the worker, never on the machine that only asks for frames.

A frame's pixels depend on nothing but the file and the frame number: a final render
keeps no view state from frame to frame except Freeze Cascades, and that holds the
cascades of the job's first frame in every worker (see ``WorkerSession.prepare``), as
``blender -a`` holds them over the same range.
"""

import dataclasses
import logging
import os
import threading
import time

from .frames import frame_done

# Test hook: the first worker process that manages to create this file dies (exit code
# 70) after rendering its first frame and before writing it, like a machine that goes
# away mid-frame; the scheduler must then hand that frame to another worker.
CRASH_ONCE_ENV = "CSM_FARM_TEST_CRASH_ONCE"

WRITTEN, PRESENT, FAILED = "written", "present", "failed"


@dataclasses.dataclass(frozen=True)
class FarmJob:
    """One farm run: the .blend (absolute path), the output pattern (absolute, with
    ``#``), whether existing frames are rendered again, the ``--set`` overrides, and the
    first frame of the range (where Freeze Cascades takes its cascades)."""
    blend_path: str
    pattern: str
    overwrite: bool = False
    overrides: tuple = ()
    first_frame: int = 1


@dataclasses.dataclass
class FrameReport:
    """What one frame task did: ``status`` is WRITTEN, PRESENT (kept, not rendered) or
    FAILED (``message`` says why, in one line). Seconds: opening the .blend (only in the
    task that opened it), rendering, writing the PNG. ``worker``: the process id."""
    frame: int
    path: str
    status: str
    message: str = ""
    open_seconds: float = 0.0
    render_seconds: float = 0.0
    write_seconds: float = 0.0
    worker: int = 0
    output: str = ""


class WorkerSession:
    """One worker process's Blender session for one ``FarmJob``: the .blend opened once,
    CSM as its engine, the ``--set`` overrides applied. A new job (another file, other
    overrides) opens its file afresh."""

    def __init__(self, job):
        import bpy
        from ..blender import cli, engine
        from ..core.captured_output import CapturedOutput
        self.job = job
        start = time.perf_counter()
        cli.keep_freed_memory()
        # The engine must be registered before the file is read, or Blender reports the
        # file's CSM engine as missing.
        cli.ensure_registered()
        with CapturedOutput() as captured:
            try:
                bpy.ops.wm.open_mainfile(filepath=job.blend_path, load_ui=False)
            except RuntimeError as error:
                raise cli.CLIError(f"cannot open {job.blend_path}: "
                                   + " ".join(str(error).split()), cli.EXIT_SCENE) from None
        self.output = captured.text
        scene = bpy.context.scene
        for override in job.overrides:
            cli.apply_override(scene.csm, override)
        render = scene.render
        render.engine = "CSM"
        render.image_settings.file_format = 'PNG'
        render.image_settings.color_mode = 'RGBA' if render.film_transparent else 'RGB'
        # Nothing a render of another file left behind may shape this file's frames.
        engine.forget_final_render_view()
        self.scene = scene
        self.open_seconds = time.perf_counter() - start
        self.prepared = False

    def prepare(self, frame):
        """Before the first frame: with Freeze Cascades on, render the job's first frame
        (and keep only its cascades) unless that is the frame asked for, so every worker
        holds the cascades ``blender -a`` would hold over the same range."""
        if self.prepared:
            return
        self.prepared = True
        if self.scene.csm.freeze_cascades and frame != self.job.first_frame:
            self._render(self.job.first_frame)

    def _render(self, frame):
        from ..blender import engine
        from ..core.captured_output import CapturedOutput
        self.scene.frame_set(frame)
        with CapturedOutput() as captured:
            result = engine.render_final(self.scene)
        return result, captured.text

    def render(self, frame, path):
        """Render ``frame`` into ``path`` (atomically: a temporary file in the same
        folder, renamed over ``path`` once complete). Returns a ``FrameReport``."""
        from ..blender import cli
        report = FrameReport(frame, path, FAILED, worker=os.getpid())
        self.prepare(frame)
        start = time.perf_counter()
        result, output = self._render(frame)
        report.render_seconds = time.perf_counter() - start
        report.output = output
        if result.error:
            report.message = f"frame {frame}: render failed: {result.error}"
            return report
        _crash_once_if_asked()
        start = time.perf_counter()
        try:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            cli.write_render_png(self.scene, path)
        except OSError as error:
            report.message = f"frame {frame}: cannot write {path}: {error.strerror}"
            return report
        except cli.CLIError as error:
            report.message = f"frame {frame}: {error}"
            return report
        report.write_seconds = time.perf_counter() - start
        report.status = WRITTEN
        return report


def _crash_once_if_asked():
    marker = os.environ.get(CRASH_ONCE_ENV)
    if not marker:
        return
    try:
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return
    os._exit(70)


# This process's session (a worker process serves one job at a time; the scheduler may
# hand it frames of another job sharing the cluster, which then reopens its own file).
_SESSION = [None]
# One Blender per process renders one frame at a time: a worker started with several
# threads (dask worker --nthreads 4) still runs its frames one after another.
_BLENDER = threading.Lock()


def session(job):
    """The process's ``WorkerSession`` for ``job``, opening the file if it is new here.
    Returns (session, seconds spent opening now)."""
    held = _SESSION[0]
    if held is not None and held.job == job:
        return held, 0.0
    _SESSION[0] = None
    _SESSION[0] = WorkerSession(job)
    return _SESSION[0], _SESSION[0].open_seconds


def scene_frames(job):
    """The file's own frames (Frame Start .. End by Frame Step), as ``blender -a`` renders
    them; opens the file in this worker, which keeps it for its frames."""
    with _BLENDER:
        scene = session(job)[0].scene
        return list(range(scene.frame_start, scene.frame_end + 1, max(scene.frame_step, 1)))


def render_frame(job, frame, path):
    """The task of one frame: render it into ``path`` unless the file is there already
    (and ``job.overwrite`` is off). Never raises for the user's file: a file that will not
    open or a frame that fails comes back as a FAILED report with one line."""
    from ..blender.cli import CLIError
    if not job.overwrite and frame_done(path):
        return FrameReport(frame, path, PRESENT, worker=os.getpid())
    with _BLENDER:
        try:
            held, open_seconds = session(job)
        except CLIError as error:
            return FrameReport(frame, path, FAILED, message=str(error), worker=os.getpid())
        report = held.render(frame, path)
    report.open_seconds = open_seconds
    if open_seconds:
        report.output = held.output + report.output
    return report


HEARTBEAT_FAILURE = "Failed to communicate with scheduler during heartbeat."


def stop_heartbeat(dask_worker):
    """Run on every local worker (``Client.run``) just before the farm closes its cluster.
    Stops the worker's heartbeat, and drops the one log record a heartbeat already in
    flight would write when the scheduler closes under it: a traceback on the user's
    terminal although nothing failed."""
    dask_worker.periodic_callbacks["heartbeat"].stop()
    logging.getLogger("distributed.worker").addFilter(
        lambda record: record.getMessage() != HEARTBEAT_FAILURE)
