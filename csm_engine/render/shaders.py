"""GLSL programs: loading from ``shaders/``, includes, uniform-block layouts, hot reload.

Owns every ``gpu.types.GPUShader`` the pipeline uses. GLSL lives as real files in the
GLSL library ``shaders/`` (the repository's top-level folder in a checkout, the package's
own copy once installed: ``core/paths.py`` finds it), or in the folder the user chose as
Shader Folder (the add-on preference; ``ShaderLibrary.folder`` says which, and
``folder_problem`` checks that a folder holds the whole library before it is read). A
program names its two stage files; the library's topical files (shadow filters, cascade
selection, BRDF, debug views...) are pulled in by ``#include "file.glsl"``, resolved here
(create-info has no include mechanism): each file at most once per stage, and each with its
own block of line numbers so compiler messages can be mapped back to ``file.glsl:line``.

The frame uniform block is described once, in ``core/frame_layout.py`` (``FRAME_LAYOUT``),
which generates both the std140 GLSL structs and the numpy packing, so the two can never
disagree; the limits and enums the GLSL uses (``MAX_*``, ``DEBUG_*``, ``PCF_*``) come from
the same module's ``glsl_defines()`` and are given to every program here.

``ShaderLibrary.reload()`` compiles everything anew and swaps only if every program
compiled: on an error the last good shaders keep running and ``last_error`` says why. The
first compile never leaves the engine without shaders: a user's folder that fails gives way
to the add-on's own.
"""

import os
import re
import sys

from ..core import bsdf_tables, paths
from ..core.captured_output import CapturedOutput
from ..core.frame_layout import FRAME_LAYOUT, glsl_defines
from ..core.material_layout import MATERIAL_LAYOUT
from ..core.material_layout import glsl_defines as material_defines
from .programs import PROGRAMS   # what each program reads and writes

# The material block as Blender declares it, for the driver's own compile of a failed
# program (shader_diagnostics knows of one block, the frame's).
_MATERIAL_BLOCK = (f"layout(std140) uniform csm_material_block "
                   f"{{ {MATERIAL_LAYOUT.type_name} material; }};\n")

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


class ShaderCompileError(Exception):
    """A GLSL program failed to compile; the message names file and line where known."""


# NOTE: Blender 4.2+ rewrites the program text and drops the file number of ``#line N id``
# from compiler messages, so each file instead gets its own block of line numbers: line n of
# file k is reported as k * LINES_PER_FILE + n, whatever the driver or Blender prints.
LINES_PER_FILE = 10000


# Preprocessor lines that may leave a conditional group: the lines after them get their
# number again (see _expand_includes).
_CONDITIONAL_END = re.compile(r"^\s*#\s*(else|elif|endif)\b")


def _expand_includes(name, directory, file_ids, depth=0, included=None):
    """Return ``name``'s source with includes inlined and ``#line`` markers for mapping.

    The GLSL library's files include what they use, so one file may be asked for twice
    (the shadow filters and the debug views both read the atlas): each file is inlined
    once per stage (``included``), later requests give nothing. After every ``#else``,
    ``#elif`` and ``#endif`` the file's own line number is set again, because a ``#line``
    inside a group the preprocessor skips is skipped too, while the skipped lines still
    count."""
    if depth > 8:
        raise ShaderCompileError(f"{name}: #include nested too deeply (a cycle?)")
    included = set() if included is None else included
    if name in included:
        return ""
    included.add(name)
    path = os.path.join(directory, name)
    try:
        with open(path, encoding="utf-8") as handle:
            text = handle.read()
    except OSError as error:
        raise ShaderCompileError(f"{path}: cannot read shader ({error.strerror})") from None
    except UnicodeDecodeError as error:
        line = error.object[:error.start].count(b"\n") + 1
        byte = error.object[error.start]
        raise ShaderCompileError(f"{name}:{line}: not UTF-8 text (byte 0x{byte:02x}); "
                                 "save the file as UTF-8") from None
    file_id = file_ids.setdefault(name, len(file_ids) + 1)
    base = file_id * LINES_PER_FILE
    out = [f"#line {base + 1}"]
    for number, line in enumerate(text.splitlines(), start=1):
        match = _INCLUDE.match(line)
        if match:
            out.append(_expand_includes(match.group(1), directory, file_ids, depth + 1,
                                        included))
            out.append(f"#line {base + number + 1}")
        else:
            out.append(line)
            if _CONDITIONAL_END.match(line):
                out.append(f"#line {base + number + 1}")
    return "\n".join(out) + "\n"


def _map_log(log, file_ids):
    """Rewrite line numbers in a compiler log to ``file.glsl:line`` (see LINES_PER_FILE)."""
    names = {i: n for n, i in file_ids.items()}

    def replace(match):
        number = int(match.group(0))
        name = names.get(number // LINES_PER_FILE)
        return f"{name}:{number % LINES_PER_FILE}" if name else match.group(0)

    return re.sub(r"(?<![\d.])\d{5,6}(?![\d.])", replace, log)


def folder_problem(folder):
    """Why ``folder`` cannot be read as the GLSL library, in a few words, or None: it must
    hold every program's stage files and every file those include (with or without an
    ``#ifdef`` around the include: some program takes each branch)."""
    if not os.path.isdir(folder):
        return "no such folder"
    pending = sorted({spec[stage] for spec in PROGRAMS.values()
                      for stage in ("vertex", "fragment")})
    seen, missing = set(), []
    while pending:
        name = pending.pop()
        if name in seen:
            continue
        seen.add(name)
        try:
            with open(os.path.join(folder, name), encoding="utf-8", errors="replace") as handle:
                pending.extend(_INCLUDE.findall(handle.read()))
        except OSError:
            missing.append(name)
    if not missing:
        return None
    # The program file everyone edits first, then the rest in name order.
    missing.sort(key=lambda name: (name != paths.SHADER_MARKER, name))
    more = f" and {len(missing) - 3} more files" if len(missing) > 3 else ""
    return f"missing {', '.join(missing[:3])}{more}"


_LOCATION = re.compile(r"[\w.-]+\.glsl:\d+")


def _error_lines(log):
    """The compiler's error lines, each with a file:line where the log has one. A location
    printed on a line just above the message (``10171 | <source>`` then ``| Error: ...``)
    is joined to it. Blender 3.4/4.2 print none at all (see shader_diagnostics)."""
    lines = log.splitlines()
    errors = []
    for index, line in enumerate(lines):
        if "error" not in line.lower() or "EGL" in line or "pyGPU_Shader" in line:
            continue
        text = line.strip(" |")
        if not _LOCATION.search(text):
            for previous in reversed(lines[max(index - 3, 0):index]):
                found = _LOCATION.search(previous)
                if found:
                    text = f"{found.group(0)}: {text}"
                    break
        errors.append(text)
    return errors


def _build(program_name, spec, directory, host_defines=()):
    import gpu

    file_ids = {}
    vertex = _expand_includes(spec["vertex"], directory, file_ids)
    fragment = _expand_includes(spec["fragment"], directory, file_ids)

    info = gpu.types.GPUShaderCreateInfo()
    interface = gpu.types.GPUStageInterfaceInfo(f"csm_{program_name}_iface")
    for name, kind, interpolation in spec["interface"]:
        getattr(interface, interpolation)(kind, name)
    for slot, (name, kind) in enumerate(spec["inputs"]):
        info.vertex_in(slot, kind, name)
    info.vertex_out(interface)
    for kind, name in spec["push"]:
        info.push_constant(kind, name)
    for slot, (kind, name) in enumerate(spec["samplers"]):
        info.sampler(slot, kind, name)
    # NOTE: create-info takes one typedef source, so both blocks' structs go in together.
    typedefs = (FRAME_LAYOUT.glsl() if spec["frame"] else "") + \
        (MATERIAL_LAYOUT.glsl() if spec.get("material") else "")
    if typedefs:
        info.typedef_source(typedefs)
    if spec["frame"]:
        info.uniform_buf(0, FRAME_LAYOUT.type_name, "frame")
    if spec.get("material"):
        info.uniform_buf(1, MATERIAL_LAYOUT.type_name, "material")
    for slot, (kind, name) in enumerate(spec["outputs"]):
        info.fragment_out(slot, kind, name)
    # A program writing gl_FragDepth says so where the API can (5.0; Metal and Vulkan need
    # it, OpenGL does not).
    if spec.get("depth_write") and hasattr(info, "depth_write"):
        info.depth_write(spec["depth_write"])
    defines = [*glsl_defines(), *material_defines(), *bsdf_tables.glsl_defines(),
               *host_defines, *spec.get("defines", ())]
    for name, value in defines:
        info.define(name, value)
    info.vertex_source(vertex)
    info.fragment_source(fragment)

    with CapturedOutput() as captured:
        try:
            shader = gpu.shader.create_from_info(info)
            failed = None
        except Exception as error:  # Blender raises a bare Exception on compile errors
            shader, failed = None, error
    if failed is not None:
        log = _map_log(captured.text, file_ids)
        errors = _error_lines(log)
        if not any(_LOCATION.search(error) for error in errors):
            # Blender 3.4/4.2 drop the location (see shader_diagnostics): ask the driver.
            from . import shader_diagnostics
            driver = shader_diagnostics.driver_log(
                spec, {"vertex": vertex, "fragment": fragment}, defines,
                typedefs + (_MATERIAL_BLOCK if spec.get("material") else ""),
                (FRAME_LAYOUT.type_name, "frame") if spec["frame"] else None)
            located = [e for e in _error_lines(_map_log(driver, file_ids)) if _LOCATION.search(e)]
            errors = located or errors
        detail = "; ".join(errors[:5]) or str(failed)
        if not _LOCATION.search(detail):
            # No location from Blender nor the driver: name the files at least.
            detail = f"in {', '.join(file_ids)}: {detail}"
        raise ShaderCompileError(f"shader '{program_name}' failed to compile: {detail}")
    # Pass through anything else the driver said (warnings), as Blender would have.
    noise = [line for line in captured.text.splitlines() if line and "EGL" not in line]
    if noise:
        print("\n".join(noise))
    return shader


# NOTE: a GPU program must not be freed while a GPU context other than the one that drew
# with it is current. F5 (``reload``) runs outside any render, with Blender's own context
# current, and a library can be dropped there too. Freeing programs at that moment made Mesa
# (llvmpipe) delete their compiled variants from the wrong context and left the render
# context's state broken: its next draw ran with no vertex shader and the process segfaulted
# (pip bpy 5.0.1 runs every final render in one long-lived context; see
# tests/bpy/engine/test_render.py). So a library never frees a program itself: programs it
# stops using wait here until ``release_retired``, which ``Pipeline.draw`` calls inside the
# context that draws.
_RETIRED = []


def release_retired():
    """Free the programs retired since the last call. Call it only where a frame is drawn
    (``Pipeline.draw``), never from an operator or at module level."""
    _RETIRED.clear()


class ShaderLibrary:
    """All programs, compiled lazily together; reload keeps the last good set on error.

    ``directory`` fixes the folder (tests); otherwise ``preferred_folder()`` (the user's
    Shader Folder preference, given by the Blender side: an absolute path, or "" for none)
    names it when set, else the add-on's own library is read."""

    def __init__(self, directory=None, preferred_folder=None):
        self.directory = directory
        self.preferred_folder = preferred_folder
        # ``#define``s of the host Blender, set by the Blender side (PRINCIPLED_V1: the
        # Principled BSDF of Blender < 4.0); a compile-time switch, because llvmpipe runs
        # both sides of an `if` on a uniform.
        self.host_defines = ()
        self._shaders = None
        self.last_error = None
        self.generation = 0
        # The folder the running programs were compiled from (None before the first).
        self.compiled_from = None

    def __del__(self):
        # A library that goes away (e.g. a temporary one in tests) frees nothing itself.
        try:
            if self._shaders:
                _RETIRED.append(self._shaders)
        except (AttributeError, TypeError):   # interpreter shutdown
            pass

    @property
    def own_folder(self):
        """The folder read when the user chose none: the one given, else the running
        add-on's own GLSL library (a checkout's shaders/, or the installed copy)."""
        return self.directory or paths.shaders_dir()

    @property
    def folder(self):
        """The folder the next compile (F5, or the first frame) reads: the user's Shader
        Folder when set, else ``own_folder``."""
        if not self.directory and self.preferred_folder is not None:
            preferred = self.preferred_folder()
            if preferred:
                return preferred
        return self.own_folder

    @property
    def folder_in_use(self):
        """The folder the running programs came from; before the first compile, the one it
        will read."""
        return self.compiled_from or self.folder

    def _compile_all(self, directory):
        problem = folder_problem(directory)
        if problem:
            raise ShaderCompileError(f"Shader Folder {directory}: {problem}")
        compiled = {}
        try:
            for name, spec in PROGRAMS.items():
                if not spec.get("on_demand"):
                    compiled[name] = _build(name, spec, directory, self.host_defines)
        except BaseException:
            _RETIRED.append(compiled)      # the programs that did compile, freed later
            raise
        return compiled

    def _use(self, shaders, directory):
        if self._shaders:
            _RETIRED.append(self._shaders)   # freed by the next draw, not here (see NOTE)
        self._shaders = shaders
        self.compiled_from = directory
        self.generation += 1

    def _compile_first(self):
        """The first compile. A user's folder that is incomplete or does not compile must
        not leave the engine without shaders: the add-on's own are compiled instead, and
        ``last_error`` says why (F5 reads the user's folder again)."""
        folder, own = self.folder, self.own_folder
        if folder != own:
            try:
                self._use(self._compile_all(folder), folder)
                return
            except ShaderCompileError as error:
                self.last_error = f"{error} (the add-on's own shaders are in use)"
                print(f"CSM: {self.last_error}", file=sys.stderr)
        self._use(self._compile_all(own), own)

    def get(self, name):
        if self._shaders is None:
            self._compile_first()
        shader = self._shaders.get(name)
        if shader is None:
            # An on-demand program (see PROGRAMS), from the folder the others came from.
            shader = self._shaders[name] = _build(name, PROGRAMS[name], self.compiled_from,
                                                  self.host_defines)
        return shader

    def release(self):
        """Drop the compiled programs (they compile again on the next ``get``); like every
        program this library stops using, they are freed by ``release_retired``."""
        if self._shaders:
            _RETIRED.append(self._shaders)
        self._shaders = None
        self.compiled_from = None

    def reload(self):
        """Recompile every program from ``folder``. Returns None on success, else the
        message (the folder is checked first: an incomplete one is named with what it
        lacks)."""
        folder = self.folder
        try:
            shaders = self._compile_all(folder)
        except ShaderCompileError as error:
            self.last_error = str(error)
            print(f"CSM: {self.last_error} (keeping the previous shaders)", file=sys.stderr)
            return self.last_error
        self._use(shaders, folder)
        self.last_error = None
        return None


# Shaders may be shared between GPU contexts (unlike framebuffers), so one library serves
# the viewport and final renders alike.
LIBRARY = ShaderLibrary()
