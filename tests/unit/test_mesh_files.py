"""Mesh files are checked before Blender's importers see them (core/mesh_files.py).

Every file here is generated: good files of each format pass, and each hostile or broken
one (a PLY count that is not a number, counts the file cannot hold, an STL whose header
lies, an OBJ whose faces point nowhere, FIFOs and devices anywhere a file is read) is
refused with one line naming the file and what is wrong.
"""

import json
import os
import struct

import pytest

from csm_engine.core import mesh_files
from csm_engine.core.mesh_files import MeshFileError, check_mesh_file

TRIANGLE = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]


def _write(path, data):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return str(path)


def _ply_ascii(vertex_count="3", face_count="1", body=None, extra_header=""):
    header = ("ply\nformat ascii 1.0\ncomment made by a test\n"
              f"element vertex {vertex_count}\nproperty float x\nproperty float y\n"
              f"property float z\n{extra_header}element face {face_count}\n"
              "property list uchar int vertex_indices\nend_header\n")
    if body is None:
        body = "".join(f"{x} {y} {z}\n" for x, y, z in TRIANGLE) + "3 0 1 2\n"
    return header + body


def _ply_binary(vertex_count=3, face_count=1, body=None):
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {vertex_count}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {face_count}\n"
              "property list uchar int vertex_indices\nend_header\n").encode()
    if body is None:
        body = b"".join(struct.pack("<3f", *v) for v in TRIANGLE) + struct.pack("<B3i", 3, 0, 1, 2)
    return header + body


def _stl_binary(triangles=1, claimed=None):
    body = b"".join(struct.pack("<12fH", 0, 0, 1, *TRIANGLE[0], *TRIANGLE[1], *TRIANGLE[2], 0)
                    for _ in range(triangles))
    count = triangles if claimed is None else claimed
    return b"binary stl".ljust(80, b" ") + struct.pack("<I", count) + body


STL_ASCII = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
             "vertex 0 1 0\nendloop\nendfacet\nendsolid t\n")
OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _refused(path, *words):
    with pytest.raises(MeshFileError) as info:
        check_mesh_file(path)
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith(str(path) + ": "), message
    for word in words:
        assert word in message, (word, message)
    return message


# ---------------------------------------------------------------------------- good files

@pytest.mark.parametrize("name, data", [
    ("ascii.ply", _ply_ascii()),
    ("crlf.ply", _ply_ascii().replace("\n", "\r\n")),
    ("binary.ply", _ply_binary()),
    ("binary.stl", _stl_binary(2)),
    ("solid_header.stl", b"solid but binary".ljust(80) + _stl_binary(1)[80:]),
    ("ascii.stl", STL_ASCII),
    ("plain.obj", OBJ),
    ("negative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3/1/1 -2/2/2 -1/3/3\n"),
    ("box.gltf", json.dumps({"asset": {"version": "2.0"}, "buffers": [
        {"uri": "data:application/octet-stream;base64,AAAA", "byteLength": 3}]})),
])
def test_good_files_pass(tmp_path, name, data):
    check_mesh_file(_write(tmp_path / name, data))


def test_gltf_with_its_buffer_and_images_passes(tmp_path):
    _write(tmp_path / "m.bin", b"\0" * 8)
    _write(tmp_path / "tex" / "a b.png", b"png")
    path = _write(tmp_path / "m.gltf", json.dumps({
        "asset": {"version": "2.0"}, "buffers": [{"uri": "m.bin", "byteLength": 8}],
        "images": [{"uri": "tex/a%20b.png"}, {"uri": "missing.png"}]}))
    check_mesh_file(path)       # a missing image is the importer's warning, not ours


# ----------------------------------------------------------------------------------- PLY

def test_ply_count_that_is_not_a_number(tmp_path):
    # 76 bytes that abort Blender's C++ importer (std::invalid_argument from stoi).
    data = ("ply\nformat ascii 1.0\nelement vertex three\nproperty float x\n"
            "end_header\n1 2 3\n")
    path = _write(tmp_path / "mesh.ply", data)
    assert os.path.getsize(path) == 76
    _refused(path, "mesh.ply: element vertex count 'three' is not a whole number")


@pytest.mark.parametrize("count, words", [
    ("-3", ["element vertex count '-3' is not a whole number"]),
    ("1.5", ["'1.5' is not a whole number"]),
    ("4000000000", ["element vertex count 4000000000 is more than the limit"]),
    ("2000000000", ["promises", "ASCII body has only 4 lines"]),
])
def test_ply_ascii_counts_must_be_whole_and_fit_the_lines(tmp_path, count, words):
    _refused(_write(tmp_path / "mesh.ply", _ply_ascii(vertex_count=count)), *words)


def test_ply_binary_counts_must_fit_the_file_size(tmp_path):
    # A huge count over a tiny body: Blender would allocate for it and die.
    message = _refused(_write(tmp_path / "mesh.ply", _ply_binary(vertex_count=2_000_000_000)),
                       "need at least", "the body has 49")
    assert "vertex 2000000000" in message
    _refused(_write(tmp_path / "faces.ply", _ply_binary(face_count=50)), "face 50")


@pytest.mark.parametrize("change", [
    # Each of these imports with its face in Blender's C++ importer (4.2 or 5.0).
    lambda t: t.replace("format ascii 1.0", "format ascii one"),
    lambda t: t.replace("format ascii 1.0", "format ascii 1.0 extra"),
    lambda t: t.replace("format ascii 1.0", "format text 1.0"),
    lambda t: t.replace("format ascii 1.0\n", ""),
    lambda t: t.replace("property float y", "property quad y"),
    lambda t: t.replace("list uchar int", "list float int"),
    lambda t: t.replace("list uchar int", "list uchar bogus"),
    lambda t: t.replace("element face 1", "element face 1 extra"),
    lambda t: t.replace("property float y", "property float y extra"),
])
def test_ply_ascii_header_oddities_blender_reads_pass(tmp_path, change):
    check_mesh_file(_write(tmp_path / "mesh.ply", change(_ply_ascii())))


def test_ply_ascii_counts_are_checked_whatever_the_format_line(tmp_path):
    data = _ply_ascii(vertex_count="2000000000").replace("format ascii 1.0", "format text 1.0")
    _refused(_write(tmp_path / "mesh.ply", data), "ASCII body has only 4 lines")
    data = _ply_ascii(vertex_count="2000000000").replace("format ascii 1.0\n", "")
    _refused(_write(tmp_path / "none.ply", data), "ASCII body has only 4 lines")


@pytest.mark.parametrize("old, new, words", [
    (b"property float y", b"property quad y", ["binary PLY", "unknown property type 'quad'"]),
    (b"list uchar int", b"list float int", ["binary PLY", "count type 'float'"]),
    (b"list uchar int", b"list uchar bogus", ["binary PLY", "unknown property type 'bogus'"]),
])
def test_binary_ply_with_types_of_unknown_size(tmp_path, old, new, words):
    # The counts cannot be checked against the file size without each property's size.
    data = _ply_binary(face_count=2_000_000_000).replace(old, new)
    _refused(_write(tmp_path / "mesh.ply", data), *words)


@pytest.mark.parametrize("change, words", [
    (lambda t: t.replace("end_header\n", "end_header\n", 1).replace("end_header", "stop"),
     ["no 'end_header'"]),
    (lambda t: "xyz\n" + t[4:], ["not a PLY file"]),
    (lambda t: t.replace("property float x\n", ""), ["x, y and z"]),
    (lambda t: t.replace("element face 1", "element face 0").replace("3 0 1 2\n", ""),
     ["has no faces"]),
])
def test_ply_header_mistakes(tmp_path, change, words):
    _refused(_write(tmp_path / "mesh.ply", change(_ply_ascii())), *words)


@pytest.mark.parametrize("line", [
    "Created by Blender3D 247 - www.blender.org, source file: ",     # Blender 2.47's export
    "frobnicate 3",
    "obj_info made by a scanner",
])
def test_ply_header_lines_the_importer_skips_pass(tmp_path, line):
    data = _ply_ascii().replace("format ascii 1.0\n", f"format ascii 1.0\n{line}\n")
    check_mesh_file(_write(tmp_path / "mesh.ply", data))
    binary = _ply_binary().replace(b"end_header", f"{line}\nend_header".encode())
    check_mesh_file(_write(tmp_path / "binary.ply", binary))


def test_ply_counts_are_checked_after_unknown_header_lines(tmp_path):
    data = _ply_ascii(vertex_count="three").replace("ply\n", "ply\nCreated by a test\n", 1)
    _refused(_write(tmp_path / "mesh.ply", data), "count 'three' is not a whole number")


def test_ply_property_before_any_element(tmp_path):
    data = "ply\nformat ascii 1.0\nproperty float x\nend_header\n"
    _refused(_write(tmp_path / "mesh.ply", data), "property before any element")


# ----------------------------------------------------------------------------------- STL

def test_stl_random_bytes(tmp_path):
    data = bytes((i * 7919 + 13) % 256 for i in range(300))
    _refused(_write(tmp_path / "noise.stl", data), "not an STL file", "300")


def test_stl_header_claiming_four_billion_triangles(tmp_path):
    _refused(_write(tmp_path / "liar.stl", _stl_binary(1, claimed=4_000_000_000)),
             "4000000000 triangles", "200000000084 bytes", "has 134")


def test_stl_size_must_match_exactly(tmp_path):
    _refused(_write(tmp_path / "long.stl", _stl_binary(2) + b"\0"), "needs exactly 184 bytes")


@pytest.mark.parametrize("data", [
    STL_ASCII.replace("solid t\n", "").replace("endsolid t\n", ""),
    b"\xef\xbb\xbf" + STL_ASCII.encode(),
])
def test_ascii_stl_without_solid_first_passes(tmp_path, data):
    # Blender reads any STL whose size is not a binary one's as ASCII and imports these.
    check_mesh_file(_write(tmp_path / "facets.stl", data))


def test_stl_without_triangles(tmp_path):
    _refused(_write(tmp_path / "empty.stl", _stl_binary(0)), "0 triangles")
    _refused(_write(tmp_path / "nofacet.stl", "solid t\nendsolid t\n"), "without any 'facet'")
    _refused(_write(tmp_path / "short.stl", b"hello"), "too short")


# ----------------------------------------------------------------------------------- OBJ

def test_obj_whose_faces_all_have_invalid_indices(tmp_path):
    data = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 5 6 7\nf 1 2 99999999999999999999\nf 0 1 2\n"
    _refused(_write(tmp_path / "bad.obj", data), "none of its 3 faces has valid vertex indices",
             "3 vertices")


def test_obj_with_one_valid_face_passes(tmp_path):
    check_mesh_file(_write(tmp_path / "mixed.obj", OBJ + "f 7 8 9\n"))


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16-be"])
def test_utf16_obj_with_a_byte_order_mark_passes(tmp_path, encoding, monkeypatch):
    # Blender's OBJ importer reads these (assimp's box_UTF16BE.obj imports with 6 faces).
    # Chunks of an odd size cut characters in half: the decoder must carry them over.
    monkeypatch.setattr(mesh_files, "_CHUNK_BYTES", 7)
    text = "# a box\r\n" + OBJ.replace("\n", "\r\n")
    data = "\ufeff".encode(encoding) + text.encode(encoding)
    check_mesh_file(_write(tmp_path / "box.obj", data))


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16-be"])
def test_utf16_obj_without_a_byte_order_mark_passes(tmp_path, encoding):
    check_mesh_file(_write(tmp_path / "box.obj", ("# box\n" + OBJ).encode(encoding)))


def test_utf16_obj_is_still_checked(tmp_path):
    data = "\ufeffv 0 0 0\nf 1 2 3\n".encode("utf-16-be")
    _refused(_write(tmp_path / "bad.obj", data), "none of its 1 faces", "1 vertices")


def test_obj_with_a_utf8_byte_order_mark_passes(tmp_path):
    check_mesh_file(_write(tmp_path / "bom.obj", b"\xef\xbb\xbf" + OBJ.encode()))


@pytest.mark.parametrize("data, words", [
    ("v 0 0 0\nv 1 0 0\n", ["without any face"]),
    ("f 1 2 3\n", ["no vertices"]),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", ["none of its 1 faces"]),
    ("v 0 0 0\nf -1 -2 -3\n", ["none of its 1 faces"]),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf a b c\n", ["line 4 refers to vertex a"]),
])
def test_obj_mistakes(tmp_path, data, words):
    _refused(_write(tmp_path / "m.obj", data), *words)


# ----------------------------------------------------------- non-regular files, sizes

def test_fifo_as_mesh_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.obj"
    os.mkfifo(fifo)
    _refused(str(fifo), "FIFO", "not a regular file")


def test_device_and_folder_as_mesh(tmp_path):
    link = tmp_path / "zero.stl"
    link.symlink_to("/dev/zero")
    _refused(str(link), "character device")
    folder = tmp_path / "folder.ply"
    folder.mkdir()
    _refused(str(folder), "a folder")


def test_empty_mesh_file(tmp_path):
    _refused(_write(tmp_path / "e.obj", b""), "empty")


def test_obj_mtllib_and_mtl_maps_must_be_regular_files(tmp_path):
    os.mkfifo(tmp_path / "pipe.mtl")
    _refused(_write(tmp_path / "a.obj", "mtllib pipe.mtl\n" + OBJ), "material library",
             "pipe.mtl", "FIFO")
    (tmp_path / "dev.mtl").symlink_to("/dev/zero")
    _refused(_write(tmp_path / "b.obj", "mtllib dev.mtl\n" + OBJ), "dev.mtl", "device")
    os.mkfifo(tmp_path / "tex.png")
    _write(tmp_path / "good.mtl", "newmtl m\nKd 1 1 1\nmap_Kd -bm 1.0 tex.png\n")
    _refused(_write(tmp_path / "c.obj", "mtllib good.mtl\n" + OBJ), "map_Kd", "tex.png", "FIFO")
    # A missing library or texture is the importer's warning, not a refusal.
    check_mesh_file(_write(tmp_path / "d.obj", "mtllib gone.mtl\n" + OBJ))


def test_mtl_larger_than_the_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(mesh_files, "MAX_MTL_BYTES", 10)
    _write(tmp_path / "big.mtl", "newmtl m\nKd 1 1 1\n")
    _refused(_write(tmp_path / "a.obj", "mtllib big.mtl\n" + OBJ), "larger than the limit")


def test_gltf_buffer_and_image_uris_must_be_regular_files(tmp_path):
    os.mkfifo(tmp_path / "pipe.bin")
    gltf = {"asset": {"version": "2.0"}, "buffers": [{"uri": "pipe.bin", "byteLength": 8}]}
    _refused(_write(tmp_path / "a.gltf", json.dumps(gltf)), "buffers[0].uri", "FIFO")
    gltf = {"asset": {"version": "2.0"}, "images": [{"uri": "/dev/zero"}]}
    _refused(_write(tmp_path / "b.gltf", json.dumps(gltf)), "images[0].uri", "device")
    gltf = {"asset": {"version": "2.0"}, "buffers": [{"uri": "gone.bin", "byteLength": 8}]}
    _refused(_write(tmp_path / "c.gltf", json.dumps(gltf)), "gone.bin", "does not exist")


def test_glb_uris_are_checked_too(tmp_path):
    os.mkfifo(tmp_path / "pipe.png")
    text = json.dumps({"asset": {"version": "2.0"}, "images": [{"uri": "pipe.png"}]}).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text
    path = _write(tmp_path / "m.glb", struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    _refused(path, "images[0].uri", "FIFO")
    _refused(_write(tmp_path / "bad.glb", b"GLTF" + b"\0" * 40), "does not start with 'glTF'")


def test_invalid_gltf_json(tmp_path):
    _refused(_write(tmp_path / "a.gltf", "{ nope"), "not a valid glTF file")
    _refused(_write(tmp_path / "b.gltf", "[1, 2]"), "not a glTF object")


def test_mesh_file_larger_than_the_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(mesh_files, "MAX_MESH_FILE_BYTES", 10)
    _refused(_write(tmp_path / "m.obj", OBJ), "larger than the limit for mesh files")


# ---------------------------------------------------------------- staying inside the scene

def _outside(path, allowed, *words):
    with pytest.raises(MeshFileError) as info:
        check_mesh_file(path, allowed)
    message = str(info.value)
    assert "\n" not in message, message
    for word in ("is outside the scene's folder", "--allow-folder") + words:
        assert word in message, (word, message)
    return message


@pytest.fixture
def tree(tmp_path):
    """A scene folder and, beside it, a folder of private files."""
    scene, private = tmp_path / "scene", tmp_path / "private"
    _write(private / "secret.png", b"not an image")
    _write(private / "lib.mtl", "newmtl m\nKd 1 1 1\n")
    _write(private / "data.bin", bytes(36))
    return scene, private


def test_obj_mtllib_outside_the_scene_is_refused_and_allowed_with_the_option(tree):
    scene, private = tree
    obj = _write(scene / "box.obj", f"mtllib {private / 'lib.mtl'}\n" + OBJ)
    _outside(obj, [str(scene)], obj + ": mtllib", "lib.mtl", str(scene))
    relative = _write(scene / "rel.obj", "mtllib ../private/lib.mtl\n" + OBJ)
    _outside(relative, [str(scene)], "mtllib ../private/lib.mtl")
    check_mesh_file(obj, [str(scene), str(private)])
    check_mesh_file(obj)        # no folders given: no confinement


def test_mtl_map_outside_the_scene_is_refused_naming_the_mtl(tree):
    scene, private = tree
    mtl = _write(scene / "box.mtl", f"newmtl m\nmap_Kd {private / 'secret.png'}\n")
    obj = _write(scene / "box.obj", "mtllib box.mtl\n" + OBJ)
    message = _outside(obj, [str(scene)], "map_Kd", "secret.png")
    assert message.startswith(mtl + ": map_Kd "), message
    for keyword in ("bump", "refl", "map_Bump -bm 0.5", "disp", "norm", "map_Ks"):
        _write(scene / "box.mtl", f"newmtl m\n{keyword} ../private/secret.png\n")
        _outside(obj, [str(scene)], keyword.split()[0])
    check_mesh_file(obj, [str(scene), str(private)])


def test_mtl_map_in_the_scene_or_the_mesh_folder_passes(tmp_path):
    scene = tmp_path / "scene"
    _write(scene / "textures/wood.png", b"png")
    _write(scene / "models/box.mtl", "newmtl m\nmap_Kd ../textures/wood.png\nmap_Ka gone.png\n")
    obj = _write(scene / "models/box.obj", "mtllib box.mtl\n" + OBJ)
    check_mesh_file(obj, [str(scene)])
    # The mesh file's own folder is allowed even when the scene folder is elsewhere.
    _write(scene / "models/box.mtl", "newmtl m\nmap_Kd box.mtl\n")
    check_mesh_file(obj, [str(tmp_path / "other")])


def _gltf(key, uri):
    document = {"asset": {"version": "2.0"}, key: [{"uri": uri, "byteLength": 36}]}
    return json.dumps(document)


def test_gltf_image_uri_outside_the_scene_is_refused(tree):
    scene, private = tree
    path = _write(scene / "m.gltf", _gltf("images", "../private/secret.png"))
    message = _outside(path, [str(scene)], "images[0].uri ../private/secret.png")
    assert message.startswith(path + ": "), message
    absolute = _write(scene / "a.gltf", _gltf("images", str(private / "secret.png")))
    _outside(absolute, [str(scene)], "images[0].uri")
    escaped = _write(scene / "e.gltf", _gltf("images", "..%2Fprivate%2Fsecret.png"))
    _outside(escaped, [str(scene)], "images[0].uri")
    check_mesh_file(path, [str(scene), str(private)])


def test_gltf_buffer_uri_outside_the_scene_is_refused(tree):
    scene, private = tree
    path = _write(scene / "m.gltf", _gltf("buffers", "../private/data.bin"))
    _outside(path, [str(scene)], "buffers[0].uri ../private/data.bin")
    check_mesh_file(path, [str(scene), str(private)])


def test_a_symlink_inside_pointing_outside_is_refused(tree):
    scene, private = tree
    _write(scene / "placeholder", b"")
    os.symlink(private / "secret.png", scene / "texture.png")
    os.symlink(private, scene / "linked")
    path = _write(scene / "m.gltf", _gltf("images", "texture.png"))
    _outside(path, [str(scene)], "images[0].uri texture.png")
    obj = _write(scene / "box.obj", "mtllib linked/lib.mtl\n" + OBJ)
    _outside(obj, [str(scene)], "mtllib linked/lib.mtl")
    check_mesh_file(path, [str(scene), str(private)])
    check_mesh_file(obj, [str(scene), str(private)])


def test_a_symlinked_scene_folder_still_counts_as_inside(tmp_path):
    real = tmp_path / "real"
    _write(real / "tex.png", b"png")
    path = _write(real / "m.gltf", _gltf("images", "tex.png"))
    os.symlink(real, tmp_path / "link")
    check_mesh_file(str(tmp_path / "link" / "m.gltf"), [str(tmp_path / "link")])
    assert mesh_files.is_inside(str(real / "tex.png"), [str(tmp_path / "link")])
    assert not mesh_files.is_inside(str(tmp_path / "realx"), [str(real)])
