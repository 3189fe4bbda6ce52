"""The CS562 JSON scene format: text in, plain data classes out.

Owns parsing and validation of scene files (see ``docs/scene-format.md`` in the shared
docs) and the lookup of the mesh files they name. Nothing here imports ``bpy``, so the
whole format is testable with plain Python.

Every problem a user can make in a scene file becomes one ``SceneFormatError`` whose
message is a single line naming the file and, where it applies, the JSON path of the
bad value (``objects[2].scale.y``) or the line and column of a syntax error.

What is accepted, beyond the strict format:
- duplicated keys (the last one wins, as in the course's real files);
- ``"translation"`` as an older spelling of ``"translate"``;
- a missing, null or empty ``"lights"`` list; a missing or null ``"directional_light"``
  (no sun) and ``"camera"`` (the builder frames the scene itself);
- missing ``translate``/``rotate`` (zero), ``scale`` (one) and ``color`` (white);
- unknown extra keys, which are ignored.

What is required: ``objects`` (a list, possibly empty), each object's ``mesh``, the
camera's ``near``, ``far`` and ``FOVy``, each point light's ``position`` and ``radius``
and the sun's ``direction``. Numbers must be finite (JSON's NaN/Infinity extensions are
rejected), scales non-zero, colours non-negative, the sun direction non-zero,
``0 < near < far``, ``0 < FOVy < 180`` degrees (and within Blender's camera range,
``CAMERA_FOV_RANGE_DEGREES``) and point-light radii positive.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

SUPPORTED_MESH_EXTENSIONS = (".gltf", ".glb", ".obj", ".ply", ".stl")

# Long values are cut in messages so that one bad value cannot flood a report line.
_MAX_SHOWN_VALUE = 40


class SceneFormatError(ValueError):
    """A scene file the user has to fix. ``str()`` is one line naming file and place."""

    def __init__(self, source, detail, path=""):
        self.source = str(source)
        self.path = path
        self.detail = detail
        where = f"{self.source}: {path}: " if path else f"{self.source}: "
        super().__init__(_one_line(where + detail))


# Blender's camera field of view limits (Camera.angle_y is 0.0064 to 3.0167 radians); a
# value past them gives a degenerate projection rather than a clamped one.
CAMERA_FOV_RANGE_DEGREES = (0.367, 172.8)


@dataclass(frozen=True)
class Vec3:
    x: float
    y: float
    z: float

    def as_tuple(self):
        return (self.x, self.y, self.z)


@dataclass(frozen=True)
class Camera:
    """The file's camera, in the file's Y-up world; angles in degrees."""
    translate: Vec3
    rotate: Vec3
    near: float
    far: float
    fov_y_degrees: float


@dataclass(frozen=True)
class SceneObject:
    """One mesh file placed by ``T(translate) * Rx * Ry * Rz * S(scale)`` (degrees)."""
    mesh: str
    translate: Vec3
    rotate: Vec3
    scale: Vec3


@dataclass(frozen=True)
class PointLight:
    """Linear falloff to zero at ``radius`` scene units; ``color`` is linear RGB."""
    position: Vec3
    color: Vec3
    radius: float


@dataclass(frozen=True)
class DirectionalLight:
    """``direction`` is where the light travels (towards the scene), not normalized."""
    direction: Vec3
    color: Vec3


@dataclass(frozen=True)
class SceneDescription:
    source: str
    objects: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    camera: Camera | None = None
    directional_light: DirectionalLight | None = None


def _one_line(text):
    return " ".join(str(text).split())


def _shown(value):
    try:
        text = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        text = repr(value)
    text = _one_line(text)
    if len(text) > _MAX_SHOWN_VALUE:
        text = text[:_MAX_SHOWN_VALUE - 3] + "..."
    return text


def _got(value):
    """'got ...' text: the kind of value, plus the value itself when it is short."""
    if value is None:
        return "got null"
    if isinstance(value, (dict, list)):
        return f"got {_type_name(value)}"
    return f"got {_type_name(value)} {_shown(value)}"


def _type_name(value):
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


class _Reader:
    """Walks the decoded JSON, raising errors that carry the JSON path."""

    def __init__(self, source):
        self.source = source

    def fail(self, path, detail):
        raise SceneFormatError(self.source, detail, path)

    def expect_object(self, value, path):
        if not isinstance(value, dict):
            self.fail(path, f"expected an object, {_got(value)}")
        return value

    def require(self, parent, key, path, what=""):
        if key not in parent:
            hint = f" ({what})" if what else ""
            self.fail(_join(path, key), f"missing{hint}")
        return parent[key]

    def number(self, value, path):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(path, f"expected a number, {_got(value)}")
        try:
            number = float(value)
        except OverflowError:
            self.fail(path, "number is too large")
        if math.isnan(number):
            self.fail(path, "NaN is not allowed (numbers must be finite)")
        if math.isinf(number):
            self.fail(path, f"{_shown(value)} is not allowed (numbers must be finite)")
        return number

    def vec3(self, value, path):
        self.expect_object(value, path)
        return Vec3(*(self.number(self.require(value, axis, path), _join(path, axis))
                      for axis in "xyz"))

    def optional_vec3(self, parent, keys, path, default):
        for key in keys:
            if key in parent:
                return self.vec3(parent[key], _join(path, key)), _join(path, key)
        return default, _join(path, keys[0])


def _join(path, key):
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else key


_ZERO = Vec3(0.0, 0.0, 0.0)
_ONE = Vec3(1.0, 1.0, 1.0)


def _read_color(reader, parent, path):
    color, color_path = reader.optional_vec3(parent, ("color",), path, _ONE)
    for axis in "xyz":
        if getattr(color, axis) < 0.0:
            reader.fail(_join(color_path, axis),
                        f"colour must not be negative, got {_shown(getattr(color, axis))}")
    return color


def _read_object(reader, value, path):
    reader.expect_object(value, path)
    mesh = reader.require(value, "mesh", path, "the mesh file to load")
    mesh_path = _join(path, "mesh")
    if not isinstance(mesh, str):
        reader.fail(mesh_path, f"expected a file path string, {_got(mesh)}")
    if not mesh.strip():
        reader.fail(mesh_path, "mesh path is empty")
    if "\x00" in mesh:
        reader.fail(mesh_path, "mesh path contains a NUL character")
    extension = os.path.splitext(mesh)[1].lower()
    if extension not in SUPPORTED_MESH_EXTENSIONS:
        reader.fail(mesh_path, f"unsupported mesh type {_shown(extension or mesh)}; "
                               f"supported: {' '.join(SUPPORTED_MESH_EXTENSIONS)}")
    translate, _ = reader.optional_vec3(value, ("translate", "translation"), path, _ZERO)
    rotate, _ = reader.optional_vec3(value, ("rotate",), path, _ZERO)
    scale, scale_path = reader.optional_vec3(value, ("scale",), path, _ONE)
    for axis in "xyz":
        if getattr(scale, axis) == 0.0:
            reader.fail(_join(scale_path, axis), "scale must not be zero (it flattens the mesh)")
    return SceneObject(mesh=mesh, translate=translate, rotate=rotate, scale=scale)


def _read_camera(reader, value, path):
    reader.expect_object(value, path)
    translate, _ = reader.optional_vec3(value, ("translate", "translation"), path, _ZERO)
    rotate, _ = reader.optional_vec3(value, ("rotate",), path, _ZERO)
    near = reader.number(reader.require(value, "near", path, "near clip distance"),
                         _join(path, "near"))
    far = reader.number(reader.require(value, "far", path, "far clip distance"),
                        _join(path, "far"))
    fov = reader.number(reader.require(value, "FOVy", path, "vertical field of view in degrees"),
                        _join(path, "FOVy"))
    if near <= 0.0:
        reader.fail(_join(path, "near"), f"must be greater than 0, got {_shown(near)}")
    if far <= near:
        reader.fail(_join(path, "far"), f"must be greater than near ({_shown(near)}), "
                                        f"got {_shown(far)}")
    if not 0.0 < fov < 180.0:
        reader.fail(_join(path, "FOVy"), f"must be between 0 and 180 degrees, got {_shown(fov)}")
    low, high = CAMERA_FOV_RANGE_DEGREES
    if not low <= fov <= high:
        reader.fail(_join(path, "FOVy"), f"{_shown(fov)} degrees is outside what a Blender "
                                         f"camera can show ({low:g} to {high:g} degrees)")
    return Camera(translate=translate, rotate=rotate, near=near, far=far, fov_y_degrees=fov)


def _read_point_light(reader, value, path):
    reader.expect_object(value, path)
    position = reader.vec3(reader.require(value, "position", path), _join(path, "position"))
    color = _read_color(reader, value, path)
    radius = reader.number(reader.require(value, "radius", path, "falloff radius"),
                           _join(path, "radius"))
    if radius <= 0.0:
        reader.fail(_join(path, "radius"), f"must be greater than 0, got {_shown(radius)}")
    return PointLight(position=position, color=color, radius=radius)


def _read_directional_light(reader, value, path):
    reader.expect_object(value, path)
    direction_path = _join(path, "direction")
    direction = reader.vec3(reader.require(value, "direction", path), direction_path)
    if direction.x == 0.0 and direction.y == 0.0 and direction.z == 0.0:
        reader.fail(direction_path, "direction has zero length (the sun needs a direction)")
    color = _read_color(reader, value, path)
    return DirectionalLight(direction=direction, color=color)


def _reject_constant(name):
    # json accepts NaN/Infinity literals; keep them as floats so the error can name the
    # JSON path where they appear (and ignore them in keys we do not read).
    return float(name.replace("Infinity", "inf"))


def _last_key_wins(pairs):
    # The course's Sponza scene repeats "x" inside a colour; the last value is the one
    # its C++ loader used.
    result = {}
    for key, value in pairs:
        result[key] = value
    return result


def _decode(text, source):
    try:
        return json.loads(text, object_pairs_hook=_last_key_wins,
                          parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise SceneFormatError(
            source, f"invalid JSON at line {err.lineno}, column {err.colno}: {err.msg}") from None
    except RecursionError:
        raise SceneFormatError(source, "invalid JSON: nested too deeply") from None
    except ValueError as err:
        # e.g. integers with thousands of digits (Python's int conversion limit)
        raise SceneFormatError(source, f"invalid JSON: {err}") from None


def parse_scene(text: str, source: str) -> SceneDescription:
    """Parse scene JSON ``text``; ``source`` names the file in error messages."""
    source = str(source)
    data = _decode(text, source)
    reader = _Reader(source)
    if not isinstance(data, dict):
        reader.fail("", f"a scene file must be a JSON object, {_got(data)}")

    objects_value = reader.require(data, "objects", "", "a scene needs an 'objects' list")
    if not isinstance(objects_value, list):
        reader.fail("objects", f"expected a list, {_got(objects_value)}")
    objects = [_read_object(reader, item, _join("objects", index))
               for index, item in enumerate(objects_value)]

    lights_value = data.get("lights")
    if lights_value is None:
        lights_value = []
    if not isinstance(lights_value, list):
        reader.fail("lights", f"expected a list, {_got(lights_value)}")
    lights = [_read_point_light(reader, item, _join("lights", index))
              for index, item in enumerate(lights_value)]

    camera = None
    if data.get("camera") is not None:
        camera = _read_camera(reader, data["camera"], "camera")

    sun = None
    if data.get("directional_light") is not None:
        sun = _read_directional_light(reader, data["directional_light"], "directional_light")

    return SceneDescription(source=source, objects=objects, lights=lights,
                            camera=camera, directional_light=sun)


def load_scene(path) -> SceneDescription:
    """Read and parse the scene file at ``path`` (UTF-8, an optional BOM is fine).

    Only a regular file of at most 64 MiB is read: a FIFO would block forever and a device
    such as /dev/zero would never end. (The largest course scene is a few kilobytes.)
    """
    import stat

    max_bytes = 64 * 1024 * 1024
    source = os.fspath(path)
    # NOTE: O_NONBLOCK makes opening a FIFO return at once; fstat on the open descriptor
    # then refuses it, with no window for a swap between a check and the read.
    def nonblocking(name, flags):
        return os.open(name, flags | getattr(os, "O_NONBLOCK", 0))

    try:
        with open(source, "rb", opener=nonblocking) as stream:
            mode = os.fstat(stream.fileno()).st_mode
            if stat.S_ISDIR(mode):
                raise IsADirectoryError
            if not stat.S_ISREG(mode):
                kind = ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
                        "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else
                        "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
                raise SceneFormatError(source, f"is {kind}, not a regular file; only regular "
                                               f"files are read as scenes")
            raw = stream.read(max_bytes + 1)
    except IsADirectoryError:
        raise SceneFormatError(source, "is a folder, not a scene file") from None
    except FileNotFoundError:
        raise SceneFormatError(source, "file not found") from None
    except PermissionError:
        raise SceneFormatError(source, "cannot read the file (permission denied)") from None
    except OSError as err:
        raise SceneFormatError(source, f"cannot read the file ({err.strerror or err})") from None
    if len(raw) > max_bytes:
        raise SceneFormatError(source, f"the file is larger than the limit of "
                                       f"{max_bytes // (1024 * 1024)} MiB for scene files")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise SceneFormatError(
            source, f"not a UTF-8 text file (bad byte at offset {err.start})") from None
    return parse_scene(text, source)


def mesh_path_candidates(mesh, scene_path, cwd=None):
    """Every place ``mesh`` may live, in lookup order, without duplicates.

    The scene file's folder comes first (our own scenes), then the current folder and
    the scene folder's ancestors (course files name meshes relative to the project root
    while living in ``data/scenes/``).
    """
    if os.sep == "/":
        # Course files written on Windows use backslashes.
        mesh = mesh.replace("\\", "/")
    mesh = os.path.expanduser(mesh)
    if os.path.isabs(mesh):
        return [os.path.normpath(mesh)]
    scene_dir = os.path.dirname(os.path.abspath(os.fspath(scene_path)))
    cwd = os.path.abspath(os.fspath(cwd) if cwd is not None else os.getcwd())
    bases = [scene_dir, cwd]
    folder = scene_dir
    while True:
        parent = os.path.dirname(folder)
        if parent == folder:
            break
        bases.append(parent)
        folder = parent
    candidates = []
    for base in bases:
        candidate = os.path.normpath(os.path.join(base, mesh))
        if candidate not in candidates:
            candidates.append(candidate)
    return candidates


def resolve_mesh_path(mesh, scene_path, cwd=None, json_path="") -> str:
    """The absolute path of an existing, readable mesh file, else ``SceneFormatError``."""
    candidates = mesh_path_candidates(mesh, scene_path, cwd)
    for candidate in candidates:
        if os.path.isfile(candidate):
            try:
                with open(candidate, "rb") as stream:
                    stream.read(1)
            except OSError as err:
                raise SceneFormatError(
                    scene_path, f"cannot read mesh file {candidate} "
                                f"({err.strerror or err})", json_path) from None
            return candidate
    raise SceneFormatError(
        scene_path, f"mesh file {_shown(mesh)} not found; tried: {', '.join(candidates)}",
        json_path)
