"""Command line: import a JSON scene, render one frame with CSM, write a PNG.

Owns the course's ``argv[1]`` = scene file, ``argv[2]`` = screenshot contract, for both
``python -m csm_engine`` (pip ``bpy``) and ``blender -b -P blender_cli.py -- ...``. Every
user mistake ends with one line on stderr and a non-zero exit code, never a traceback.

Importing this module needs neither ``bpy`` nor numpy: ``--help``, the argument checks and
the message that says how to run it answer on any Python 3, ``--list-settings`` on any
with numpy (it reads the settings model, not Blender); only rendering needs ``bpy``.
"""

import argparse
import importlib
import math
import os
import re
import shlex
import struct
import sys
import types

from ..core import paths
from ..core.captured_output import CapturedOutput

EXIT_USAGE = 2
EXIT_SCENE = 3
EXIT_RENDER = 4
EXIT_OUTPUT = 5
EXIT_NO_BLENDER = 6      # this Python cannot import bpy (or numpy): run it another way


class CLIError(Exception):
    def __init__(self, message, code=EXIT_USAGE):
        super().__init__(message)
        self.code = code


DEFAULT_SCREENSHOT = "csm_default.png"


def build_parser(prog="python -m csm_engine"):
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Render a CS562-style JSON scene with the CSM engine and save a PNG.",
        epilog=f"A .blend's animation: {prog} FILE.blend --frames 1-240 --output "
               "renders/f_####.png --workers N (see docs/animations-and-farms.md).")
    parser.add_argument("scene", nargs="?", help="scene .json (default: the bundled scene)")
    parser.add_argument("screenshot", nargs="?",
                        help=f"PNG to write, exactly this path (default: {DEFAULT_SCREENSHOT})")
    parser.add_argument("--resolution", default="1280x720", metavar="WxH",
                        help="image size in pixels (default 1280x720)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="SETTING=VALUE",
                        help="override a CSM setting, e.g. --set pcf_radius=2 "
                             "--set debug_view=CASCADES (repeatable)")
    parser.add_argument("--allow-folder", dest="allowed_folders", action="append", default=[],
                        metavar="DIR",
                        help="let the scene's meshes, material libraries, textures and glTF "
                             "buffers be read from DIR too (repeatable; by default only the "
                             "scene's folder and each mesh file's folder)")
    parser.add_argument("--list-settings", action="store_true",
                        help="print every setting (identifier, default or --set value, unit, "
                             "allowed values, what it does) and exit")
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
    enum items and hard range in the settings model. ``csm`` is the scene's CSM settings
    or any object with one attribute per setting."""
    from ..core import settings_model
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


def open_scene(scene_path=None, overrides=(), resolution=None, allowed_folders=()):
    """The one session set-up every command shares: reset Blender to an empty factory
    scene, register the add-on, import ``scene_path`` (None: an empty scene; "default":
    the bundled scene) reading also from ``allowed_folders`` (``--allow-folder``), apply
    ``--set`` overrides, and size the render. Returns the scene. A broken scene file or
    setting raises CLIError with a one-line reason."""
    import bpy
    from ..core import scene_format
    from . import scene_builder

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    if scene_path == "default":
        scene_path = paths.default_scene_path()
    if scene_path is not None:
        try:
            scene_builder.import_scene_file(scene_path, scene,
                                            allowed_folders=allowed_folders)
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


# How a setting's Blender unit or subtype reads after a number. Angles are stored in
# radians and shown in degrees, as Blender's fields show them.
UNIT_SYMBOLS = {"LENGTH": "m", "DISTANCE": "m", "ROTATION": "°", "ANGLE": "°",
                "VELOCITY": "m/s", "TIME": "s", "TIME_ABSOLUTE": "s", "PIXEL": "px",
                "PERCENTAGE": "%"}
ANGLE_UNITS = {"ROTATION", "ANGLE"}


def unit_symbol(setting):
    """The unit a setting's numbers are in ("m", "px", "°", ...), "" for plain numbers."""
    for key in (setting.unit, setting.subtype):
        if key in UNIT_SYMBOLS:
            return UNIT_SYMBOLS[key]
    return ""


def format_number(value, setting):
    """A setting's number as a person writes it: 0.9 (never 0.8999999761581421), 100
    rather than 100.0, an angle in degrees."""
    if not isinstance(value, float):
        return str(value)
    if ANGLE_UNITS & {setting.unit, setting.subtype}:
        value = math.degrees(value)
    # The fewest digits that give back the same float32, the precision Blender stores: a
    # value read from Blender and the same value typed in print alike.
    shortest = value
    for digits in range(1, 10):
        candidate = float(f"{value:.{digits}g}")
        if _float32(candidate) == _float32(value):
            shortest = candidate
            break
    text = repr(shortest)
    return text[:-2] if text.endswith(".0") else text


def _float32(value):
    try:
        return struct.unpack("f", struct.pack("f", value))[0]
    except OverflowError:
        return value


def format_value(value, setting):
    """``value`` of ``setting`` as --set takes it back: on/off, an enum's identifier, a
    number with its unit, a vector's components separated by commas."""
    from ..core import settings_model
    if setting.kind == settings_model.BOOLEAN:
        return "on" if value else "off"
    if setting.kind == settings_model.ENUM:
        return str(value)
    if setting.kind == settings_model.FLOAT_VECTOR:
        text = ", ".join(format_number(v, setting) for v in value)
    else:
        text = format_number(value, setting)
    unit = unit_symbol(setting)
    return f"{text} {unit}" if unit else text


def allowed_values(setting):
    """What ``--set`` accepts for ``setting``, from the settings model: an enum's
    identifiers, on/off, or the hard range with its unit (a limit that is only the stored
    type's own is left out)."""
    from ..core import settings_model
    if setting.kind == settings_model.ENUM:
        return "one of " + ", ".join(setting.identifiers)
    if setting.kind == settings_model.BOOLEAN:
        return "on or off"
    unit = unit_symbol(setting)
    suffix = f" {unit}" if unit else ""
    low, high = (None if limit is None else format_number(limit, setting)
                 for limit in (setting.min, setting.max))
    if low is not None and high is not None:
        text = f"{low} to {high}{suffix}"
    elif low is not None:
        text = f"{low}{suffix} or more"
    elif high is not None:
        text = f"up to {high}{suffix}"
    else:
        text = "any number"
    if setting.subtype == "FACTOR":
        text = "a fraction, " + text
    if setting.kind == settings_model.FLOAT_VECTOR:
        text += " each"
    return text


def first_sentence(text):
    """A description's first sentence (a ".." inside a range does not end it)."""
    match = re.search(r"(?<!\.)\.(\s|$)", text)
    return text[:match.start() + 1] if match else text


def settings_listing(values=None):
    """Every setting as two lines: ``identifier = value unit   [allowed values]``, then
    its label and the first sentence of its description. ``values`` maps identifiers to
    values (default: the model's defaults). All of it comes from the settings model."""
    from ..core import settings_model
    values = values or {}
    heads = []
    for setting in settings_model.SETTINGS:
        value = values.get(setting.identifier, setting.default)
        heads.append(f"{setting.identifier} = {format_value(value, setting)}")
    width = max(len(head) for head in heads) + 3
    lines = []
    for head, setting in zip(heads, settings_model.SETTINGS):
        lines.append(f"{head:<{width}}[{allowed_values(setting)}]")
        lines.append(f"    {setting.name}: {first_sentence(setting.description)}")
    return lines


def list_settings(overrides=()):
    """Print ``settings_listing`` with ``--set`` overrides applied (checked as a render
    would check them); needs numpy, not Blender."""
    from ..core import settings_model
    values = types.SimpleNamespace(**{s.identifier: s.default for s in settings_model.SETTINGS})
    for override in overrides:
        apply_override(values, override)
    try:
        for line in settings_listing(vars(values)):
            print(line)
        sys.stdout.flush()
    except BrokenPipeError:
        # The reader stopped early (``| head``), which is no error; pointing stdout at
        # the null device keeps Python's own flush at exit from reporting it again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


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


def shell_path(path):
    """``path`` as the user types it from the current folder: relative below it,
    absolute elsewhere, quoted for the shell."""
    relative = os.path.relpath(path)
    if relative.startswith(os.pardir):
        return shlex.quote(path)
    return shlex.quote(relative if os.sep in relative else "." + os.sep + relative)


def no_blender_message(error, argv, prog):
    """One line for a Python that cannot import ``bpy`` (``error``): what is missing and
    the commands that render the same ``argv``, with paths that work from here."""
    args = shlex.join(argv)
    tail = " " + args if args else ""
    missing = getattr(error, "name", None)
    if missing == "bpy":
        what = f"{sys.executable} has no bpy, Blender's Python module"
    elif missing == "numpy":
        what = f"{sys.executable} has no numpy"
    else:
        what = f"{sys.executable} cannot import bpy ({' '.join(str(error).split())})"
    dev = os.path.join(paths.CHECKOUT_DIR, "dev")
    bridge = f"blender -b -P {shell_path(os.path.join(paths.PACKAGE_DIR, 'blender_cli.py'))} --"
    if os.path.isfile(dev):
        venv = shell_path(os.path.join(paths.CHECKOUT_DIR, ".venv", "bin", "python"))
        ways = (f"{shell_path(dev)} render{tail} (sets up pip bpy), "
                f"{venv} -m csm_engine{tail} (once set up), or {bridge}{tail}")
    else:
        ways = (f"pip install bpy (Python 3.11) and {prog}{tail} again, "
                f"or {bridge}{tail}")
    return f"{what}; run it with {ways}"


def require(module, argv, prog):
    """Import ``module`` (bpy or numpy), or stop with ``no_blender_message``."""
    try:
        importlib.import_module(module)
    except ImportError as error:
        raise CLIError(no_blender_message(error, argv, prog), EXIT_NO_BLENDER) from None


def check_positionals(args, prog):
    """Refuse a screenshot given where the scene goes (``shot.png`` alone, or the two
    swapped): it would otherwise be read as a scene file and reported as not found."""
    if args.scene and args.scene.lower().endswith(".png"):
        scene = args.screenshot if args.screenshot and not args.screenshot.lower().endswith(
            ".png") else "scene.json"
        raise CLIError(f"{args.scene}: that is the screenshot; the scene file comes first: "
                       f"{prog} {shlex.quote(scene)} {shlex.quote(args.scene)}")


def run(argv, prog="python -m csm_engine"):
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    check_positionals(args, prog)
    resolution = parse_resolution(args.resolution)
    if args.list_settings:
        require("numpy", argv, prog)
        list_settings(args.overrides)
        return 0
    require("bpy", argv, prog)
    from . import engine
    scene_path = args.scene or paths.default_scene_path()
    shot = screenshot_path(DEFAULT_SCREENSHOT if args.screenshot is None else args.screenshot,
                           scene_path)
    scene = open_scene(scene_path, args.overrides, resolution, args.allowed_folders)
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


# glibc's allocator maps blocks over its threshold fresh from the kernel and trims freed
# memory back to it, so each frame's multi-MB render result and read-back buffers
# page-fault on every 4 KiB page first written (10-30 ms a 1280x720 frame here). The
# Blender program links jemalloc, which keeps freed memory; a Python process of our own
# (this command, a farm worker, the benchmark) keeps it too, with these limits.
_MMAP_THRESHOLD_BYTES = 64 << 20
_TRIM_THRESHOLD_BYTES = 256 << 20


def keep_freed_memory():
    """In a process of our own on glibc: keep freed blocks for the next frame instead of
    handing them back to the kernel (see the note above). Elsewhere nothing."""
    import ctypes
    import ctypes.util
    import platform
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3         # from malloc.h
    return bool(libc.mallopt(m_mmap_threshold, _MMAP_THRESHOLD_BYTES)) and \
        bool(libc.mallopt(m_trim_threshold, _TRIM_THRESHOLD_BYTES))


def main(argv=None, prog="python -m csm_engine"):
    argv = sys.argv[1:] if argv is None else argv
    keep_freed_memory()
    from ..farm import command as farm      # FILE.blend --frames ...: the animation farm
    if farm.is_farm_command(argv):
        return farm.main(argv, prog)
    return run_reporting_errors(run, argv, prog, "csm")


def exit_process(code):
    """Leave with ``code``: through ``compat.exit_process`` once bpy is loaded (pip bpy
    4.2 needs it), plainly on a Python that never loaded it (compat imports bpy)."""
    if sys.modules.get("bpy") is not None:
        from .compat import exit_process as exit_blender
        exit_blender(code)
    sys.exit(code)


def console_main():
    """The ``csm-render`` console command (pip installs): ``python -m csm_engine`` under
    its own name, with the same exit codes."""
    exit_process(main(prog="csm-render"))
