"""Hostile scene input on every host: pip bpy 5.0, pip bpy 4.2 and Debian's Blender 3.4.

Blender's C++ PLY importer (4.x, 5.x) aborts the whole process on a PLY whose element
count is not a number or does not fit the file, and a FIFO named as a scene or by a mesh
blocks any reader forever. Each host runs a script in a subprocess that imports these
inputs through ``scene_builder.import_scene_file``; every one must end in a one-line
``SceneImportError`` and the script must exit 0 (a crash would be 134 or 139, a hang the
time limit). Also 300 references to one small glTF must import well within the limit, as
one copies object.
The package is copied from this checkout into the host's working folder.
"""


import pytest

pytestmark = pytest.mark.hosts


# Runs inside the host. argv (after "--" for blender): working folder. Prints CSM_RESULT.
HOST_SCRIPT = r'''
import json, os, struct, sys, threading, time
argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
work = argv[0]
sys.path.insert(0, work)
os.chdir(work)
import bpy
from csm_engine.blender import scene_builder

bpy.ops.wm.read_factory_settings(use_empty=True)
cases = os.path.join(work, "cases")
os.makedirs(cases)


def write(name, data):
    path = os.path.join(cases, name)
    with open(path, "wb") as stream:
        stream.write(data if isinstance(data, bytes) else data.encode())
    return path


def scene_for(name, meshes):
    objects = [{"mesh": mesh, "translate": {"x": 3.0 * i, "y": 0.0, "z": 0.0}}
               for i, mesh in enumerate(meshes)]
    return write(name, json.dumps({"objects": objects}))


def fifo(name):
    path = os.path.join(cases, name)
    os.mkfifo(path)
    # A watchdog opens the other end later, so a blocked reader ends instead of hanging.
    def release():
        time.sleep(20)
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass
    threading.Thread(target=release, daemon=True).start()
    return path


def box_gltf(folder):
    os.makedirs(folder, exist_ok=True)
    positions = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    blob = b"".join(struct.pack("<3f", *p) for p in positions) + struct.pack("<3H", 0, 1, 2) + b"\0\0"
    with open(os.path.join(folder, "tri.bin"), "wb") as stream:
        stream.write(blob)
    document = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
                "nodes": [{"mesh": 0}],
                "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
                "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                               "min": [0, 0, 0], "max": [1, 1, 0]},
                              {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
                "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                                {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
                "buffers": [{"uri": "tri.bin", "byteLength": len(blob)}]}
    path = os.path.join(folder, "tri.gltf")
    with open(path, "w") as stream:
        json.dump(document, stream)
    return path


ply_header = ("ply\nformat {fmt} 1.0\nelement vertex {count}\nproperty float x\n"
              "property float y\nproperty float z\nelement face 1\n"
              "property list uchar int vertex_indices\nend_header\n")
gltf = box_gltf(os.path.join(cases, "tri"))
inputs = {
    "ply count 'three'": scene_for("three.json", [write(
        "three.ply", "ply\nformat ascii 1.0\nelement vertex three\nproperty float x\n"
                     "end_header\n1 2 3\n")]),
    "ply count 4000000000": scene_for("huge.json", [write(
        "huge.ply", ply_header.format(fmt="ascii", count=4000000000) + "0 0 0\n3 0 0 0\n")]),
    "ply binary count past the file": scene_for("binary.json", [write(
        "binary.ply", ply_header.format(fmt="binary_little_endian", count=1500000000).encode()
        + b"\0" * 40)]),
    "stl random bytes": scene_for("noise.json", [write(
        "noise.stl", bytes((i * 7919 + 13) % 256 for i in range(300)))]),
    "stl claiming 4e9 triangles": scene_for("liar.json", [write(
        "liar.stl", b"x" * 80 + struct.pack("<I", 4000000000) + b"\0" * 50)]),
    "obj with only bad indices": scene_for("badobj.json", [write(
        "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 5 6 7\n")]),
    "fifo scene": fifo("pipe.json"),
    "fifo mtllib": scene_for("mtl.json", [write(
        "m.obj", "mtllib " + os.path.basename(fifo("pipe.mtl")) + "\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")]),
}
result = {"blender": bpy.app.version_string, "cases": {}}
for name, path in inputs.items():
    start = time.perf_counter()
    try:
        scene_builder.import_scene_file(path)
        outcome = "imported"
    except scene_builder.SceneImportError as error:
        outcome = "SceneImportError: " + str(error)
    except Exception as error:
        outcome = f"{type(error).__name__}: {error}"
    result["cases"][name] = {"outcome": outcome, "seconds": time.perf_counter() - start,
                             "objects": len(bpy.data.objects)}

many = scene_for("many.json", [gltf] * 300)
start = time.perf_counter()
collection = scene_builder.import_scene_file(many)
copies = [o for o in collection.all_objects if o.name.endswith(" copies)")]
result["many"] = {"seconds": time.perf_counter() - start,
                  "copies objects": [o.name for o in copies],
                  "copies": sum(len(o.data.vertices) for o in copies),
                  "mesh data": len({o.data.name for o in collection.all_objects
                                    if o.type == "MESH" and o not in copies})}
print("CSM_RESULT " + json.dumps(result), flush=True)
sys.stdout.flush()
os._exit(0)
'''

EXPECTED = {
    "ply count 'three'": "element vertex count 'three' is not a whole number",
    "ply count 4000000000": "element vertex count 4000000000 is more than the limit",
    "ply binary count past the file": "need at least",
    "stl random bytes": "not an STL file",
    "stl claiming 4e9 triangles": "4000000000 triangles",
    "obj with only bad indices": "none of its 1 faces has valid vertex indices",
    "fifo scene": "FIFO",
    "fifo mtllib": "FIFO",
}


@pytest.mark.parametrize("host", ["blender 3.4", "bpy 4.2", "bpy 5.0"])
def test_hostile_input_is_a_clean_error_on_every_host(hosts, host_dir, host):
    run = hosts.run_script_with_package(host, host_dir, HOST_SCRIPT)
    assert run.returncode == 0 and run.result, run.describe()
    blender = run.result["blender"]
    for name, words in EXPECTED.items():
        case = run.result["cases"][name]
        outcome = case["outcome"]
        assert outcome.startswith("SceneImportError: ") and words in outcome, \
            f"{blender}: {name}: {outcome}"
        assert "\n" not in outcome and "Traceback" not in outcome, f"{blender}: {outcome}"
        # Refused before the importer: no waiting for a FIFO's watchdog, nothing created.
        assert case["seconds"] < 10.0, f"{blender}: {name} took {case['seconds']:.1f} s"
        assert case["objects"] == 0, f"{blender}: {name} left {case['objects']} objects"
    many = run.result["many"]
    # The file imported once, and one copies object with a vertex per reference
    # (importing each reference took ~40 s for 300).
    assert many["copies"] == 300 and len(many["copies objects"]) == 1 and \
        many["mesh data"] == 1, f"{blender}: {many}"
    assert many["seconds"] < 15.0, f"{blender}: 300 references took {many['seconds']:.1f} s"
