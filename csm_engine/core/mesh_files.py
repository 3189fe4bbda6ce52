"""Checks a mesh file before any Blender importer sees it.

Owns what must hold for a mesh file to be safe to hand to Blender's own importers: the
file and every file it makes the importer read (a glTF's buffers and images, an OBJ's
material libraries and their texture maps) are regular files, not FIFOs or devices that
would block or never end; sizes are within limits; and the headers agree with the file
(PLY element counts are whole numbers that fit in the file, a binary STL's triangle count
matches its size exactly, an OBJ has faces whose vertex indices exist). Blender's C++
importers abort the whole process on some malformed headers (a PLY count that is not a
number), and report success with an empty mesh on others; both are refused here with one
line naming the file and the problem. Nothing else is refused: what the importers skip or
read (header lines of other exporters, comments, UTF-16 OBJ text) goes on to them, since
the checks are there to stop what Blender cannot survive, not to enforce each format's
letter. Given allowed folders, it also keeps the importer inside them: a referenced file
that resolves (symbolic links followed) outside them and the mesh file's own folder is
refused, so a scene cannot make Blender read the rest of the disk. Plain standard library:
no Blender, no numpy.

``check_mesh_file(path, allowed_folders)`` is the entry point; it raises ``MeshFileError``.
"""

import codecs
import json
import os
import re
import stat
import struct
from types import MappingProxyType
from urllib.parse import unquote

MEBIBYTE = 1024 * 1024
# A mesh file past this is refused before import (a real scan of tens of millions of
# triangles is a few GiB; beyond that Blender runs out of memory rather than importing).
MAX_MESH_FILE_BYTES = 4 * 1024 * MEBIBYTE
# The JSON part of a glTF (a .gltf file, or a .glb's JSON chunk) and an OBJ's .mtl file.
MAX_GLTF_JSON_BYTES = 256 * MEBIBYTE
MAX_MTL_BYTES = 16 * MEBIBYTE
# A PLY header (the text up to end_header).
MAX_PLY_HEADER_BYTES = 1 * MEBIBYTE
# Element counts (PLY elements, STL triangles) are stored as 32-bit signed integers in
# Blender's importers.
MAX_ELEMENT_COUNT = 2 ** 31 - 1

_CHUNK_BYTES = 4 * MEBIBYTE


class MeshFileError(ValueError):
    """A mesh file that must not be imported; ``str()`` is one line starting with the file."""

    def __init__(self, path, detail):
        self.path = str(path)
        self.detail = detail
        super().__init__(" ".join(f"{self.path}: {detail}".split()))


def _kind_of(mode):
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def regular_file_size(path, owner=None, what="file"):
    """Size in bytes of ``path`` if it is a regular file (symbolic links followed).

    ``owner`` is the file whose reference led here, named in the message; ``what`` says
    what the file is to the owner ("buffer file", "material library").
    """
    owner = path if owner is None else owner
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise MeshFileError(owner, f"{what} {path} does not exist") from None
    except OSError as err:
        raise MeshFileError(owner, f"cannot read {what} {path} ({err.strerror or err})") from None
    if not stat.S_ISREG(info.st_mode):
        subject = what if owner == path else f"{what} {path}"
        raise MeshFileError(owner, f"{subject} is {_kind_of(info.st_mode)}, not a regular "
                                   f"file; only regular files are read")
    return info.st_size


def read_regular_file(path, limit, owner=None, what="file"):
    """The bytes of a regular file of at most ``limit`` bytes, opened without blocking.

    NOTE: the file is opened with O_NONBLOCK and checked with fstat on the open descriptor,
    so a FIFO swapped in after a stat() cannot make the read block.
    """
    owner = path if owner is None else owner
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise MeshFileError(owner, f"{what} {path} does not exist") from None
    except OSError as err:
        raise MeshFileError(owner, f"cannot read {what} {path} ({err.strerror or err})") from None
    with os.fdopen(fd, "rb") as stream:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            subject = what if owner == path else f"{what} {path}"
            raise MeshFileError(owner, f"{subject} is {_kind_of(mode)}, not a regular file; "
                                       f"only regular files are read")
        data = stream.read(limit + 1)
    if len(data) > limit:
        raise MeshFileError(owner, f"{what} {path} is larger than the limit of "
                                   f"{_size_text(limit)}")
    return data


def _size_text(count):
    if count >= MEBIBYTE and count % MEBIBYTE == 0:
        return f"{count // MEBIBYTE} MiB"
    return f"{count} bytes"


def _chunks(path, start=0):
    with open(path, "rb") as stream:
        stream.seek(start)
        while True:
            chunk = stream.read(_CHUNK_BYTES)
            if not chunk:
                return
            yield chunk


def _shown(text, limit=40):
    text = text if isinstance(text, str) else text.decode("utf-8", "replace")
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


# ----------------------------------------------------------------------------------- PLY

_PLY_TYPE_BYTES = MappingProxyType({
    "char": 1, "uchar": 1, "short": 2, "ushort": 2, "int": 4, "uint": 4,
    "float": 4, "double": 8,
    "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4, "uint32": 4,
    "float32": 4, "float64": 8,
})
_PLY_INTEGER_TYPES = frozenset({"char", "uchar", "short", "ushort", "int", "uint",
                                "int8", "uint8", "int16", "uint16", "int32", "uint32"})
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
_WHOLE_NUMBER = re.compile(r"^[0-9]+$")


class _PlyElement:
    def __init__(self, name, count):
        self.name = name
        self.count = count
        self.properties = []        # (name, fixed size or None, list count size or None)

    def min_bytes(self):
        """Smallest binary size of one instance: fixed properties, plus each list's count."""
        return sum(size if size is not None else count_size
                   for _, size, count_size in self.properties)


def _read_ply_header(path):
    with open(path, "rb") as stream:
        head = stream.read(MAX_PLY_HEADER_BYTES)
    end = re.search(rb"(^|\n)end_header[ \t]*\r?\n", head)
    if end is None:
        if not head.startswith(b"ply"):
            raise MeshFileError(path, "not a PLY file (it does not start with 'ply')")
        raise MeshFileError(path, f"no 'end_header' line in the first "
                                  f"{_size_text(MAX_PLY_HEADER_BYTES)}")
    return head[:end.end()], end.end()


def check_ply(path, size, allowed=None):
    header, body_start = _read_ply_header(path)
    try:
        text = header.decode("ascii")
    except UnicodeDecodeError as err:
        raise MeshFileError(path, f"PLY header is not ASCII text (byte {err.start})") from None
    lines = text.replace("\r", "").split("\n")
    if lines[0].strip() != "ply":
        raise MeshFileError(path, "not a PLY file (the first line is not 'ply')")
    # Blender's importers read headers with extra words after a line's fields, a format
    # version that is not a number, or property types they do not know in an ASCII body;
    # only what decides how much the importer reads (counts, sizes) is checked.
    file_format = None
    unsized = None      # why a binary body's size cannot be checked, if it cannot
    elements = []
    for number, line in enumerate(lines[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        keyword = words[0]
        where = f"header line {number}"
        if keyword == "end_header":
            break
        if keyword == "format":
            if len(words) >= 2 and words[1] in _PLY_FORMATS:
                file_format = words[1]
        elif keyword == "element":
            if len(words) < 3:
                raise MeshFileError(path, f"{where}: expected 'element <name> <count>', got "
                                          f"{_shown(line)!r}")
            name, count_text = words[1], words[2]
            if not _WHOLE_NUMBER.match(count_text):
                raise MeshFileError(path, f"element {_shown(name)} count {_shown(count_text)!r} "
                                          f"is not a whole number")
            count = int(count_text)
            if count > MAX_ELEMENT_COUNT:
                raise MeshFileError(path, f"element {_shown(name)} count {count} is more than "
                                          f"the limit of {MAX_ELEMENT_COUNT}")
            elements.append(_PlyElement(name, count))
        elif keyword == "property":
            if not elements:
                # Blender 4.2's importer dies on this (segmentation fault).
                raise MeshFileError(path, f"{where}: a property before any element")
            element = elements[-1]
            if len(words) >= 2 and words[1] == "list":
                if len(words) < 5:
                    raise MeshFileError(path, f"{where}: expected 'property list <count type> "
                                              f"<item type> <name>', got {_shown(line)!r}")
                count_type, item_type, name = words[2], words[3], words[4]
                if count_type not in _PLY_INTEGER_TYPES:
                    unsized = unsized or (f"{where}: list count type {_shown(count_type)!r} "
                                          f"is not an integer type")
                elif item_type not in _PLY_TYPE_BYTES:
                    unsized = unsized or f"{where}: unknown property type {_shown(item_type)!r}"
                element.properties.append((name, None, _PLY_TYPE_BYTES.get(count_type, 0)))
            else:
                if len(words) < 3:
                    raise MeshFileError(path, f"{where}: expected 'property <type> <name>', "
                                              f"got {_shown(line)!r}")
                if words[1] not in _PLY_TYPE_BYTES:
                    unsized = unsized or f"{where}: unknown property type {_shown(words[1])!r}"
                element.properties.append((words[2], _PLY_TYPE_BYTES.get(words[1], 0), None))
        # Any other line (a "Created by Blender3D 247" that Blender itself once wrote, a
        # keyword of some other exporter) is skipped by Blender's importers as by this check.
    if file_format is None:
        # Some importers read a PLY without a known format line as ASCII, others refuse
        # it; its body is checked as ASCII, the most a reader can take from it.
        file_format = "ascii"
    if file_format != "ascii" and unsized is not None:
        # The size of an instance is unknown, so the counts cannot be checked against the
        # file (and Blender's importers cannot read such a binary body anyway).
        raise MeshFileError(path, f"binary PLY: {unsized}")
    by_name = {element.name: element for element in elements}
    vertex = by_name.get("vertex")
    names = {name for name, _, _ in vertex.properties} if vertex else set()
    if vertex is None or not {"x", "y", "z"} <= names:
        raise MeshFileError(path, "no 'vertex' element with x, y and z properties")
    face = by_name.get("face")
    if face is None or face.count == 0:
        raise MeshFileError(path, "has no faces (no 'face' element, or its count is 0): "
                                  "nothing to draw")
    if vertex.count == 0:
        raise MeshFileError(path, "element vertex count is 0 but faces need vertices")
    body = size - body_start
    if file_format == "ascii":
        # Every element instance takes at least one line of an ASCII body.
        needed = sum(element.count for element in elements)
        lines_found = 0
        last = b"\n"
        for chunk in _chunks(path, body_start):
            lines_found += chunk.count(b"\n")
            last = chunk[-1:]
            if lines_found >= needed:
                break
        if last != b"\n":
            lines_found += 1
        if lines_found < needed:
            counts = ", ".join(f"{e.name} {e.count}" for e in elements)
            raise MeshFileError(path, f"the header promises {needed} elements ({counts}) but "
                                      f"the ASCII body has only {lines_found} lines")
    else:
        needed = sum(element.count * element.min_bytes() for element in elements)
        if needed > body:
            counts = ", ".join(f"{e.name} {e.count}" for e in elements)
            raise MeshFileError(path, f"the header promises elements ({counts}) that need at "
                                      f"least {needed} bytes but the body has {body}")


# ----------------------------------------------------------------------------------- STL

def check_stl(path, size, allowed=None):
    # Blender's importers read an STL as binary exactly when its size is 84 + 50 x the
    # triangle count of its header, and as ASCII otherwise, 'solid' first or not.
    with open(path, "rb") as stream:
        head = stream.read(84)
    count = None
    if len(head) == 84:
        (count,) = struct.unpack("<I", head[80:84])
        if size == 84 + 50 * count:
            if count == 0:
                raise MeshFileError(path, "binary STL with 0 triangles: nothing to draw")
            if count > MAX_ELEMENT_COUNT:
                raise MeshFileError(path, f"{count} triangles is more than the limit of "
                                          f"{MAX_ELEMENT_COUNT}")
            return
    for chunk in _overlapping_chunks(path, 16):
        if b"facet" in chunk:
            return
    if head.lstrip()[:5].lower() == b"solid":
        raise MeshFileError(path, "ASCII STL without any 'facet': nothing to draw")
    if count is None:
        raise MeshFileError(path, f"not an STL file: {size} bytes is too short for a binary "
                                  f"STL (84 bytes of header) and there is no 'facet' of an "
                                  f"ASCII STL")
    raise MeshFileError(path, f"not an STL file: a binary STL's header says {count} triangles, "
                              f"which needs exactly {84 + 50 * count} bytes, but the file has "
                              f"{size}; and read as an ASCII STL it has no 'facet'")


def _overlapping_chunks(path, overlap):
    """Chunks that overlap by ``overlap`` bytes, so a word cut at a boundary is still found."""
    tail = b""
    for chunk in _chunks(path):
        yield tail + chunk
        tail = chunk[-overlap:]


# ----------------------------------------------------------------------------------- OBJ

def _obj_index(text, vertices_so_far):
    """1-based vertex index of one face corner ('7', '7/1', '-1//3'), or None if invalid."""
    head = text.split(b"/", 1)[0]
    try:
        index = int(head)
    except ValueError:
        return None
    if index < 0:
        index = vertices_so_far + index + 1
        return index if index >= 1 else None
    return index if 1 <= index <= MAX_ELEMENT_COUNT else None


def _line_paths(rest):
    """Candidate file names on an OBJ/MTL line: the whole rest and each word of it."""
    rest = rest.strip()
    candidates = [rest] if rest else []
    candidates += [word for word in rest.split() if word != rest]
    return candidates


ALLOW_HINT = "allow other folders with the Allowed Folders preference or --allow-folder"


def is_inside(path, folders):
    """Whether ``path``, symbolic links resolved, lies in one of ``folders`` (resolved too)."""
    real = os.path.realpath(path)
    for folder in folders:
        root = os.path.realpath(folder)
        if real == root or real.startswith(root.rstrip(os.sep) + os.sep):
            return True
    return False


def confine(owner, target, reference, allowed):
    """Refuse ``target`` (what ``owner`` names as ``reference``) when it resolves outside
    the ``allowed`` folders; the first of them is the scene's folder. ``None``: no limit."""
    if allowed is not None and not is_inside(target, allowed):
        where = allowed[0] if allowed else os.path.dirname(os.path.abspath(owner))
        raise MeshFileError(owner, f"{reference} is outside the scene's folder {where} ({ALLOW_HINT})")


def _check_referenced(owner, folders, name, what, allowed=None, keyword=None, referrer=None):
    """Refuse a referenced file that exists but is not a regular file, or lies outside the
    allowed folders. Missing files are left to the importer, which reports them as
    warnings and goes on (and reads nothing). ``referrer``: the file whose line names it,
    when that is not ``owner`` (an OBJ's MTL)."""
    for folder in folders:
        candidate = os.path.join(folder, name)
        if os.path.lexists(candidate):
            confine(referrer or owner, candidate, f"{keyword or what} {_shown(name, 400)}", allowed)
            regular_file_size(candidate, owner, what)
            return candidate
    return None


def _check_mtl(obj_path, mtl_path, allowed=None):
    text = read_regular_file(mtl_path, MAX_MTL_BYTES, obj_path, "material library")
    folders = [os.path.dirname(mtl_path), os.path.dirname(obj_path)]
    for line in text.splitlines():
        words = line.split(None, 1)
        if len(words) != 2:
            continue
        keyword = words[0].lower()
        if keyword.startswith(b"map_") or keyword in (b"bump", b"disp", b"decal", b"refl",
                                                      b"norm"):
            rest = words[1].decode("utf-8", "replace")
            what = f"{_shown(words[0])} texture of {os.path.basename(mtl_path)}"
            for name in _line_paths(rest):
                _check_referenced(obj_path, folders, name, what, allowed,
                                  words[0].decode("utf-8", "replace"), mtl_path)


_UTF16_BOMS = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)


def _obj_text_chunks(path):
    """The OBJ's text as UTF-8 chunks. Blender's OBJ importer reads UTF-16 files too (with
    a byte-order mark, or without one: text whose first character has a zero byte on one
    side), so those are decoded first, a chunk at a time; a UTF-8 byte-order mark is
    dropped."""
    with open(path, "rb") as stream:
        start = stream.read(3)
    chunks = _chunks(path)
    encoding = None
    if start[:2] in _UTF16_BOMS:
        encoding = "utf-16"
    elif len(start) >= 2 and start[0] != 0 and start[1] == 0:
        encoding = "utf-16-le"
    elif len(start) >= 2 and start[0] == 0 and start[1] != 0:
        encoding = "utf-16-be"
    if encoding is not None:
        decoder = codecs.getincrementaldecoder(encoding)(errors="replace")
        for chunk in chunks:
            yield decoder.decode(chunk).encode("utf-8")
        yield decoder.decode(b"", final=True).encode("utf-8")
        return
    for chunk in chunks:
        if start == codecs.BOM_UTF8:
            chunk, start = chunk[3:], b""
        yield chunk


def check_obj(path, size, allowed=None):
    folder = os.path.dirname(path)
    vertices = 0
    faces = 0
    # Positive indices may point forward; a face is valid when its largest index exists
    # by the end, so keep the smallest such maximum over faces that are otherwise valid.
    smallest_needed = None
    first_bad = None
    remainder = b""
    line_number = 0
    for chunk in _obj_text_chunks(path):
        lines = (remainder + chunk).split(b"\n")
        remainder = lines.pop()
        for line in lines:
            line_number += 1
            vertices, faces, smallest_needed, first_bad = _obj_line(
                path, folder, line, line_number, vertices, faces, smallest_needed, first_bad,
                allowed)
    if remainder:
        line_number += 1
        vertices, faces, smallest_needed, first_bad = _obj_line(
            path, folder, remainder, line_number, vertices, faces, smallest_needed, first_bad,
            allowed)
    if faces == 0:
        raise MeshFileError(path, "OBJ without any face ('f' line): nothing to draw")
    if vertices == 0:
        raise MeshFileError(path, f"OBJ with {faces} faces but no vertices ('v' lines)")
    if smallest_needed is None or smallest_needed > vertices:
        detail = f"; line {first_bad[0]} refers to vertex {_shown(first_bad[1])}" \
            if first_bad else ""
        raise MeshFileError(path, f"none of its {faces} faces has valid vertex indices (the "
                                  f"file has {vertices} vertices{detail})")


def _obj_line(path, folder, line, line_number, vertices, faces, smallest_needed, first_bad,
              allowed=None):
    stripped = line.lstrip()
    if stripped.startswith(b"v ") or stripped.startswith(b"v\t"):
        return vertices + 1, faces, smallest_needed, first_bad
    if stripped.startswith(b"f ") or stripped.startswith(b"f\t"):
        corners = stripped.split()[1:]
        largest = 0
        for corner in corners:
            index = _obj_index(corner, vertices)
            if index is None:
                largest = None
                if first_bad is None:
                    first_bad = (line_number, corner.split(b"/", 1)[0])
                break
            if index > vertices and first_bad is None:
                # Only a hint for the message: the vertex may still come later in the file.
                first_bad = (line_number, str(index).encode())
            largest = max(largest, index)
        if largest is not None and len(corners) >= 3:
            if smallest_needed is None or largest < smallest_needed:
                smallest_needed = largest
        elif largest is not None and first_bad is None:
            first_bad = (line_number, b" ".join(corners) or b"(nothing)")
        return vertices, faces + 1, smallest_needed, first_bad
    if stripped.startswith(b"mtllib"):
        rest = stripped[len(b"mtllib"):].decode("utf-8", "replace")
        for name in _line_paths(rest):
            mtl = _check_referenced(path, [folder], name, "material library", allowed,
                                    "mtllib")
            if mtl is not None:
                _check_mtl(path, mtl, allowed)
    return vertices, faces, smallest_needed, first_bad


# ---------------------------------------------------------------------------------- glTF

def _gltf_document(path, size):
    if path.lower().endswith(".glb"):
        with open(path, "rb") as stream:
            header = stream.read(20)
        if len(header) < 20 or header[:4] != b"glTF":
            raise MeshFileError(path, "not a binary glTF file (it does not start with 'glTF')")
        _, _, chunk_length, chunk_type = struct.unpack("<III4s", header[4:20])
        if chunk_type != b"JSON":
            raise MeshFileError(path, "binary glTF whose first chunk is not JSON")
        if chunk_length > MAX_GLTF_JSON_BYTES:
            raise MeshFileError(path, f"JSON chunk of {chunk_length} bytes is larger than the "
                                      f"limit of {_size_text(MAX_GLTF_JSON_BYTES)}")
        if 20 + chunk_length > size:
            raise MeshFileError(path, f"JSON chunk of {chunk_length} bytes does not fit in the "
                                      f"file ({size} bytes)")
        with open(path, "rb") as stream:
            stream.seek(20)
            raw = stream.read(chunk_length)
    else:
        if size > MAX_GLTF_JSON_BYTES:
            raise MeshFileError(path, f"a .gltf file is JSON text; {size} bytes is larger than "
                                      f"the limit of {_size_text(MAX_GLTF_JSON_BYTES)}")
        with open(path, "rb") as stream:
            raw = stream.read(MAX_GLTF_JSON_BYTES + 1)
    try:
        document = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        detail = str(err).split("\n")[0]
        raise MeshFileError(path, f"not a valid glTF file ({detail})") from None
    if not isinstance(document, dict):
        raise MeshFileError(path, "not a valid glTF file (not a glTF object)")
    return document


def check_gltf(path, size, allowed=None):
    document = _gltf_document(path, size)
    folder = os.path.dirname(path)
    for key, what, required in (("buffers", "buffer file", True), ("images", "image", False)):
        entries = document.get(key, [])
        if not isinstance(entries, list):
            raise MeshFileError(path, f"not a valid glTF file ('{key}' is not a list)")
        for index, entry in enumerate(entries):
            uri = entry.get("uri") if isinstance(entry, dict) else None
            if not isinstance(uri, str) or uri.startswith("data:"):
                continue
            target = os.path.join(folder, unquote(uri))
            if "\x00" in target:
                raise MeshFileError(path, f"{key}[{index}].uri contains a NUL character")
            confine(path, target, f"{key}[{index}].uri {_shown(uri, 400)}", allowed)
            if not os.path.lexists(target):
                if required:
                    raise MeshFileError(path, f"needs buffer file {target} ({key}[{index}].uri), "
                                              f"which does not exist")
                continue        # a missing image is the importer's warning, not an error
            regular_file_size(target, path, f"{what} ({key}[{index}].uri)")


# ---------------------------------------------------------------------------------- entry

_CHECKS = MappingProxyType({".ply": check_ply, ".stl": check_stl, ".obj": check_obj,
                            ".gltf": check_gltf, ".glb": check_gltf})


def check_mesh_file(path, allowed_folders=None):
    """Raise ``MeshFileError`` unless ``path`` is safe to hand to Blender's importer.

    ``allowed_folders``: the scene's folder first, then any others the user allowed; every
    file the mesh file references must resolve inside them or the mesh file's own folder.
    ``None`` checks no folders (a bare file check, as the compatibility sweep needs)."""
    path = os.fspath(path)
    allowed = None
    if allowed_folders is not None:
        allowed = [os.fspath(folder) for folder in allowed_folders]
        allowed.append(os.path.dirname(os.path.abspath(path)))
    size = regular_file_size(path, what="mesh file")
    if size > MAX_MESH_FILE_BYTES:
        raise MeshFileError(path, f"{size} bytes is larger than the limit for mesh files "
                                  f"({_size_text(MAX_MESH_FILE_BYTES)})")
    if size == 0:
        raise MeshFileError(path, "the file is empty")
    check = _CHECKS.get(os.path.splitext(path)[1].lower())
    if check is not None:
        try:
            check(path, size, allowed)
        except OSError as err:
            raise MeshFileError(path, f"cannot read the file ({err.strerror or err})") from None
