"""Command line: import a JSON scene, render one frame with CSM, write a PNG.

Owns the course's ``argv[1]`` = scene file, ``argv[2]`` = screenshot contract, for both
``python -m csm_engine`` (pip ``bpy``) and ``blender -b -P blender_cli.py -- ...``. Every
user mistake ends with one line on stderr and a non-zero exit code, never a traceback.
"""

import argparse
import os
import re
import sys

from ..core import settings_model
from ..core.captured_output import CapturedOutput

EXIT_USAGE = 2
EXIT_SCENE = 3
EXIT_RENDER = 4
EXIT_OUTPUT = 5


class CLIError(Exception):
    def __init__(self, message, code=EXIT_USAGE):
        super().__init__(message)
        self.code = code


def build_parser(prog="python -m csm_engine"):
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Render a CS562-style JSON scene with the CSM engine and save a PNG.")
    parser.add_argument("scene", nargs="?", help="scene .json (default: the bundled scene)")
    parser.add_argument("screenshot", nargs="?", default="csm_default.png",
                        help="PNG to write, exactly this path (default: csm_default.png)")
    parser.add_argument("--resolution", default="1280x720", metavar="WxH",
                        help="image size in pixels (default 1280x720)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="SETTING=VALUE",
                        help="override a CSM setting, e.g. --set pcf_radius=2 "
                             "--set debug_view=CASCADES (repeatable)")
    parser.add_argument("--list-settings", action="store_true",
                        help="print every setting with its default and exit")
    return parser


def parse_resolution(text):
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise CLIError(f"--resolution: expected WIDTHxHEIGHT like 1280x720, got '{text}'")
    if not (1 <= width <= 16384 and 1 <= height <= 16384):
        raise CLIError(f"--resolution: {width}x{height} is outside 1..16384 pixels")
    return width, height


def apply_override(csm, text):
    """Set one CSM property from 'name=value' text, checked against the setting's kind,
    enum items and hard range in the settings model."""
    if "=" not in text:
        raise CLIError(f"--set: expected SETTING=VALUE, got '{text}'")
    name, value = (part.strip() for part in text.split("=", 1))
    setting = settings_model.BY_IDENTIFIER.get(name)
    if setting is None:
        known = ", ".join(sorted(settings_model.BY_IDENTIFIER))
        raise CLIError(f"--set: unknown setting '{name}'. Settings: {known}")
    is_vector = setting.kind == settings_model.FLOAT_VECTOR
    try:
        if setting.kind == settings_model.BOOLEAN:
            lowered = value.lower()
            if lowered not in {"1", "0", "true", "false", "on", "off", "yes", "no"}:
                raise ValueError
            parsed = lowered in {"1", "true", "on", "yes"}
        elif setting.kind == settings_model.ENUM:
            items = setting.identifiers
            if value.upper() not in items:
                raise CLIError(f"--set {name}: '{value}' is not one of {', '.join(items)}")
            parsed = value.upper()
        else:
            cast = int if setting.kind == settings_model.INT else float
            if is_vector:
                parsed = [cast(v) for v in value.split(",")]
                if len(parsed) != setting.size:
                    raise ValueError
                values = parsed
            else:
                parsed = cast(value)
                values = [parsed]
            hard_min, hard_max = setting.hard_range
            for v in values:
                if v != v or v in (float("inf"), float("-inf")):
                    raise ValueError
                if v < hard_min or v > hard_max:
                    raise CLIError(f"--set {name}: {v} is outside {hard_min:g}..{hard_max:g}")
    except ValueError:
        kind = "float" if is_vector else setting.kind.lower()
        raise CLIError(f"--set {name}: '{value}' is not a valid {kind}"
                       + (" list" if is_vector else ""))
    setattr(csm, name, parsed)


def ensure_registered():
    """Register the add-on unless Blender already has it enabled (as extension or add-on)."""
    import bpy
    if hasattr(bpy.types.Scene, "csm") and "CSM" in {
            getattr(e, "bl_idname", None) for e in bpy.types.RenderEngine.__subclasses__()}:
        return
    from .. import register
    register()


def open_scene(scene_path=None, overrides=(), resolution=None):
    """The one session set-up every command shares: reset Blender to an empty factory
    scene, register the add-on, import ``scene_path`` (None: an empty scene; "default":
    the bundled scene), apply ``--set`` overrides, and size the render. Returns the scene.
    A broken scene file or setting raises CLIError with a one-line reason."""
    import bpy
    from ..core import paths, scene_format
    from . import scene_builder

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    if scene_path == "default":
        scene_path = paths.default_scene_path()
    if scene_path is not None:
        try:
            scene_builder.import_scene_file(scene_path, scene)
        except (scene_format.SceneFormatError, scene_builder.SceneImportError) as error:
            raise CLIError(str(error), EXIT_SCENE)
    for override in overrides:
        apply_override(scene.csm, override)
    render = scene.render
    if resolution is not None:
        render.resolution_x, render.resolution_y = resolution
    render.resolution_percentage = 100
    # The course's programs show plain sRGB; Filmic/AgX would wash the image out.
    scene.view_settings.view_transform = 'Standard'
    return scene


def list_settings(scene):
    for setting in settings_model.SETTINGS:
        print(f"{setting.identifier} = {getattr(scene.csm, setting.identifier)!r}"
              f"  # {setting.description}")


def screenshot_path(text, scene_path):
    """The absolute path the screenshot goes to, exactly as named, or CLIError: only
    ``.png``, never a folder or the scene file itself, into a folder that exists."""
    if not text or not text.strip():
        raise CLIError("the screenshot path is empty: name a .png file")
    # Blender reads a leading "//" as "next to the .blend"; on the command line it is
    # just the root folder.
    path = os.path.abspath(text)
    if path.startswith("//"):
        path = "/" + path.lstrip("/")
    if os.path.isdir(path):
        raise CLIError(f"cannot write '{text}': it is a folder; name a .png file in it")
    if os.path.splitext(path)[1].lower() != ".png":
        raise CLIError(f"cannot write '{text}': screenshots are PNG only, "
                       "name the file with .png")
    if scene_path and os.path.exists(path) and os.path.exists(scene_path) \
            and os.path.samefile(path, scene_path):
        raise CLIError(f"cannot write '{text}': it is the scene file")
    folder = os.path.dirname(path)
    if not os.path.isdir(folder):
        raise CLIError(f"cannot write '{text}': folder '{folder}' does not exist")
    return path


def write_render_png(scene, path):
    """Save the last render's image to exactly ``path`` (replacing it only once the new
    image is complete), or raise CLIError with the system's reason."""
    import tempfile
    import bpy
    image = bpy.data.images.get("Render Result")
    if image is None:
        raise CLIError("the render produced no image", EXIT_RENDER)
    folder = os.path.dirname(path)
    try:
        handle, temporary = tempfile.mkstemp(prefix=".csm-", suffix=".png", dir=folder)
        os.close(handle)
    except OSError as error:
        raise CLIError(f"cannot write '{path}': {error.strerror}", EXIT_OUTPUT) from None
    try:
        # mkstemp makes a private (0600) file; the screenshot gets the permissions any
        # new file of the user's gets.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)
        image.save_render(temporary, scene=scene)
        if os.path.getsize(temporary) == 0:
            raise CLIError(f"cannot write '{path}': Blender wrote an empty file", EXIT_OUTPUT)
        os.replace(temporary, path)
    except (OSError, RuntimeError) as error:
        reason = getattr(error, "strerror", None) or " ".join(str(error).split())
        raise CLIError(f"cannot write '{path}': {reason}", EXIT_OUTPUT) from None
    finally:
        if os.path.exists(temporary):
            os.remove(temporary)


# What Blender and the GL driver print during a render that says nothing to the user of
# a command line: EGL's start-up complaints (harmless with llvmpipe and headless EGL), its
# surfaceless fallback notice, Blender's per-stage "Fra:1 Mem:..." lines, and the engine's
# own reports, which this command prints itself as "csm: error:" / "csm: warning:".
NOISE = re.compile(r"^(EGL Error \(0x[0-9a-fA-F]+\)|Managed to successfully fallback to "
                   r"surfaceless EGL|Fra:\d+ Mem:|(Error|Warning): CSM: )")


def pass_through(text):
    """Print what a render printed, without the lines in NOISE."""
    for line in text.splitlines():
        if line.strip() and not NOISE.match(line):
            print(line, file=sys.stderr)


def run(argv, prog="python -m csm_engine"):
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    resolution = parse_resolution(args.resolution)
    if args.list_settings:
        list_settings(open_scene())
        return 0
    from ..core import paths
    from . import engine
    scene_path = args.scene or paths.default_scene_path()
    shot = screenshot_path(args.screenshot, scene_path)
    scene = open_scene(scene_path, args.overrides, resolution)
    render = scene.render
    render.engine = "CSM"
    render.image_settings.file_format = 'PNG'
    render.image_settings.color_mode = 'RGBA' if render.film_transparent else 'RGB'
    with CapturedOutput() as captured:
        result = engine.render_final(scene)
    pass_through(captured.text)
    if result.error:
        raise CLIError("render failed: " + result.error, EXIT_RENDER)
    write_render_png(scene, shot)
    for warning in result.warnings:
        print(f"csm: warning: {warning}", file=sys.stderr)
    print(f"csm: wrote {shot} ({resolution[0]}x{resolution[1]})")
    return 0


def run_reporting_errors(run_command, argv, prog, label):
    """Run a command-line tool; a user's mistake becomes one line on stderr and its exit
    code. Shared by this CLI and the measuring tools."""
    argv = sys.argv[1:] if argv is None else argv
    try:
        return run_command(argv, prog)
    except CLIError as error:
        print(f"{label}: error: {error}", file=sys.stderr)
        return error.code


def main(argv=None, prog="python -m csm_engine"):
    return run_reporting_errors(run, argv, prog, "csm")


def console_main():
    """The ``csm-render`` console command (pip installs): ``python -m csm_engine`` under
    its own name, with the same exit codes."""
    from .compat import exit_process
    exit_process(main(prog="csm-render"))
