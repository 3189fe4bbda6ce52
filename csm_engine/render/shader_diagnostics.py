"""Finding ``file.glsl:line`` for a shader compile error when Blender's log has none.

Owns the fallback compile that locates GLSL errors on Blender 3.4 and 4.2. Those versions
parse the driver's message (Mesa: ``0:10150(18): error: ...``), then look the line up in
their own concatenated source; our ``#line`` blocks (see ``shaders.LINES_PER_FILE``) point
past its end, so Blender prints an empty ``|`` row and the location is lost. After
Blender's compile has failed, and only then, this module compiles the same assembled stage
sources again with raw OpenGL calls (the ``bgl`` module on 3.4; ctypes into the system GL
library on pip bpy 4.2, whose ``bgl`` functions are all None), in the context Blender just
used, with declarations generated from the same ``PROGRAMS`` entry, and returns the
driver's raw log for ``shaders._map_log``. Blender 5.0 keeps the location in its own log,
so this never runs there unless that changes.

Nothing here runs unless a compile already failed, and every failure of the fallback
itself (no GL library, no current context, Metal/Vulkan) just returns no log.
"""

import re

# GPUShaderCreateInfo type names -> GLSL.
_SAMPLERS = {
    "FLOAT_2D": "sampler2D", "FLOAT_2D_ARRAY": "sampler2DArray", "FLOAT_3D": "sampler3D",
    "FLOAT_CUBE": "samplerCube", "FLOAT_1D": "sampler1D", "DEPTH_2D": "sampler2DShadow",
    "DEPTH_2D_ARRAY": "sampler2DArrayShadow", "INT_2D": "isampler2D", "UINT_2D": "usampler2D",
    "FLOAT_BUFFER": "samplerBuffer",
}
_QUALIFIER = {"smooth": "smooth", "flat": "flat", "no_perspective": "noperspective"}


def _glsl_type(kind):
    """``VEC3`` -> ``vec3``, ``FLOAT`` -> ``float``, ``MAT4`` -> ``mat4``, ``IVEC2`` -> ``ivec2``."""
    return kind.lower()


def declarations(spec, stage, defines, typedefs, uniform_block):
    """The GLSL that Blender would generate before ``stage``'s source ("vertex"/"fragment").

    ``defines``: (name, value) pairs; ``typedefs``: GLSL text; ``uniform_block``:
    (type name, instance name) or None."""
    out = []
    out += [f"#define {name} {value}" for name, value in defines]
    out.append(f"#define GPU_{stage.upper()}_SHADER")
    if typedefs:
        out.append(typedefs.rstrip("\n"))
    if uniform_block:
        type_name, instance = uniform_block
        out.append(f"layout(std140) uniform csm_{instance}_block {{ {type_name} {instance}; }};")
    out += [f"uniform {_glsl_type(kind)} {name};" for kind, name in spec.get("push", ())]
    out += [f"uniform {_SAMPLERS.get(kind, 'sampler2D')} {name};"
            for kind, name in spec.get("samplers", ())]
    if stage == "vertex":
        out += [f"layout(location = {slot}) in {_glsl_type(kind)} {name};"
                for slot, (name, kind) in enumerate(spec.get("inputs", ()))]
        direction = "out"
    else:
        out += [f"layout(location = {slot}) out {_glsl_type(kind)} {name};"
                for slot, (kind, name) in enumerate(spec.get("outputs", ()))]
        direction = "in"
    out += [f"{_QUALIFIER.get(interp, 'smooth')} {direction} {_glsl_type(kind)} {name};"
            for name, kind, interp in spec.get("interface", ())]
    return "\n".join(out) + "\n"


# OpenGL enums (the same on every platform).
GL_FRAGMENT_SHADER = 0x8B30
GL_VERTEX_SHADER = 0x8B31
GL_COMPILE_STATUS = 0x8B81
GL_INFO_LOG_LENGTH = 0x8B84
GL_SHADING_LANGUAGE_VERSION = 0x8B8C


class _BglGL:
    """The GL calls needed, through Blender's ``bgl`` (3.4; pip bpy 4.2 ships it stubbed)."""

    def __init__(self):
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import bgl
        if not callable(getattr(bgl, "glCreateShader", None)):
            raise RuntimeError("bgl has no GL functions")
        self.bgl = bgl

    def version_string(self):
        return self.bgl.glGetString(GL_SHADING_LANGUAGE_VERSION) or ""

    def compile_log(self, kind, source):
        bgl = self.bgl
        shader = bgl.glCreateShader(kind)
        if not shader:
            return ""
        try:
            bgl.glShaderSource(shader, source)
            bgl.glCompileShader(shader)
            status = bgl.Buffer(bgl.GL_INT, 1)
            bgl.glGetShaderiv(shader, GL_COMPILE_STATUS, status)
            if status[0]:
                return ""
            size = bgl.Buffer(bgl.GL_INT, 1)
            bgl.glGetShaderiv(shader, GL_INFO_LOG_LENGTH, size)
            capacity = max(int(size[0]), 1) + 1
            length = bgl.Buffer(bgl.GL_INT, 1)
            text = bgl.Buffer(bgl.GL_BYTE, capacity)
            bgl.glGetShaderInfoLog(shader, capacity, length, text)
            return bytes((b + 256) % 256 for b in text[:length[0]]).decode("utf-8", "replace")
        finally:
            bgl.glDeleteShader(shader)


class _CtypesGL:
    """The same calls straight from the system's OpenGL library, for the context Blender
    has current (pip bpy 4.2, whose ``bgl`` functions are all None)."""

    def __init__(self):
        import ctypes
        import ctypes.util
        import sys
        self.ctypes = ctypes
        if sys.platform == "win32":
            library = ctypes.WinDLL("opengl32")
            loader = library.wglGetProcAddress
            loader.restype, loader.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
            if not library.wglGetCurrentContext():
                raise RuntimeError("no current GL context")

            def get(name, restype, *argtypes):
                address = loader(name.encode())
                if not address:
                    function = getattr(library, name)
                    function.restype, function.argtypes = restype, list(argtypes)
                    return function
                return ctypes.WINFUNCTYPE(restype, *argtypes)(address)
        else:
            if sys.platform == "darwin":
                candidates = ["/System/Library/Frameworks/OpenGL.framework/OpenGL"]
            else:   # GLVND's libOpenGL dispatches to whichever GLX/EGL context is current
                candidates = ["libOpenGL.so.0", "libGL.so.1", ctypes.util.find_library("GL")]
            library = None
            for candidate in filter(None, candidates):
                try:
                    library = ctypes.CDLL(candidate)
                    break
                except OSError:
                    continue
            if library is None:
                raise RuntimeError("no OpenGL library")

            def get(name, restype, *argtypes):
                function = getattr(library, name)
                function.restype, function.argtypes = restype, list(argtypes)
                return function
        c = ctypes
        self.glGetString = get("glGetString", c.c_char_p, c.c_uint)
        self.glCreateShader = get("glCreateShader", c.c_uint, c.c_uint)
        self.glShaderSource = get("glShaderSource", None, c.c_uint, c.c_int,
                                  c.POINTER(c.c_char_p), c.POINTER(c.c_int))
        self.glCompileShader = get("glCompileShader", None, c.c_uint)
        self.glGetShaderiv = get("glGetShaderiv", None, c.c_uint, c.c_uint, c.POINTER(c.c_int))
        self.glGetShaderInfoLog = get("glGetShaderInfoLog", None, c.c_uint, c.c_int,
                                      c.POINTER(c.c_int), c.c_char_p)
        self.glDeleteShader = get("glDeleteShader", None, c.c_uint)
        if not self.glGetString(GL_SHADING_LANGUAGE_VERSION):
            raise RuntimeError("no current GL context")

    def version_string(self):
        return (self.glGetString(GL_SHADING_LANGUAGE_VERSION) or b"").decode("ascii", "replace")

    def compile_log(self, kind, source):
        c = self.ctypes
        shader = self.glCreateShader(kind)
        if not shader:
            return ""
        try:
            text = c.c_char_p(source.encode("utf-8"))
            self.glShaderSource(shader, 1, c.byref(text), None)
            self.glCompileShader(shader)
            status = c.c_int(0)
            self.glGetShaderiv(shader, GL_COMPILE_STATUS, c.byref(status))
            if status.value:
                return ""
            size = c.c_int(0)
            self.glGetShaderiv(shader, GL_INFO_LOG_LENGTH, c.byref(size))
            capacity = max(size.value, 1) + 1
            buffer = c.create_string_buffer(capacity)
            length = c.c_int(0)
            self.glGetShaderInfoLog(shader, capacity, c.byref(length), buffer)
            return buffer.raw[:length.value].decode("utf-8", "replace")
        finally:
            self.glDeleteShader(shader)


def _open_gl():
    """A GL-calling object for the current context, or None."""
    for backend in (_BglGL, _CtypesGL):
        try:
            return backend()
        except Exception:
            continue
    return None


def _glsl_version(gl):
    """The newest of 330/400/410/420/430 the current context supports ("4.50 ..." -> 430)."""
    try:
        major, minor = re.match(r"(\d+)\.(\d+)", gl.version_string()).groups()
        version = int(major) * 100 + int(minor)
    except Exception:
        return 330
    for candidate in (430, 420, 410, 400):
        if version >= candidate:
            return candidate
    return 330


def driver_log(spec, sources, defines, typedefs="", uniform_block=None):
    """Compile the assembled ``sources`` ({"vertex": text, "fragment": text}) with raw
    OpenGL calls and return the driver's error log, each line prefixed with its stage;
    '' when there is no OpenGL context to use (callers then keep Blender's message)."""
    import sys
    if "bpy" in sys.modules:
        import gpu
        backend = getattr(gpu.platform, "backend_type_get", lambda: "OPENGL")()
        if backend != "OPENGL":     # Metal / Vulkan: no GL context to ask
            return ""
    gl = _open_gl()
    if gl is None:
        return ""
    try:
        version = _glsl_version(gl)
        kinds = {"vertex": GL_VERTEX_SHADER, "fragment": GL_FRAGMENT_SHADER}
        logs = []
        for stage in ("vertex", "fragment"):
            full = (f"#version {version} core\n"
                    + declarations(spec, stage, defines, typedefs, uniform_block) + sources[stage])
            log = gl.compile_log(kinds[stage], full)
            # Mesa: "0:10150(17): error: ..." -> "10150(17): error: ..." ("0" = string).
            logs += [f"{stage}: " + re.sub(r"^\d+:(?=\d{5})", "", line.strip())
                     for line in log.splitlines() if line.strip()]
        return "\n".join(logs)
    except Exception:   # a driver that refuses the calls: nothing to add
        return ""
