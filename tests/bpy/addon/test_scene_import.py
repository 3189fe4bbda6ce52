"""JSON scene import into Blender (pip bpy, in process).

Checks what a user sees after File > Import > CSM Scene: the committed scenes and every
sample of the format doc load with the right objects, lights and camera, the camera
looks at the content, re-importing replaces, and every bad file gives one clear message
while leaving the Blender scene exactly as it was.
"""

import json
import math
import os
import struct

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view

from csm_engine.core import conventions
from csm_engine.blender import scene_builder
from csm_engine.blender.scene_builder import SceneImportError

from tests.conftest import REPO
SCENES = os.path.join(REPO, "csm_engine", "data", "scenes")
C = conventions.zup_from_yup()

SCENE_SHADOW = """{
    "camera":
    {
        "translate": { "x": -190.0, "y": 40.0, "z": 50.0 },
        "rotate":    { "x": 0.0, "y": 100, "z": 0.0 },
        "near": 0.1,
        "far": 500.0,
        "FOVy": 30.0
    },
    "objects":
    [
        {
            "mesh": "data/gltf/vokselia/vokselia.gltf",
            "translate": { "x": 0.0, "y": 0.0, "z": 0.0 },
            "rotate":    { "x": 0.0, "y": 0.0, "z": 0.0 },
            "scale":     { "x": 100, "y": 100, "z": 100 }
        }
    ],
    "lights": [],
    "directional_light":
    {
        "direction": { "x": 0.3, "y": -0.6, "z": -0.7 },
        "color":     { "x": 1.0, "y": 1.0, "z": 1.0 }
    }
}"""

_SPONZA_LIGHT = """{ "position": {"x": %s, "y": 60.0, "z": %s},
              "color": {"x": 1.0, "x": 1.0, "y": 0.95, "z": 0.65},
              "radius": 30 }"""
# The assignment-1 sample from the doc, completed to its six lights (all radius 30).
SPONZA = """{
"camera": { "translate": {"x": -90.0, "y": 40.0, "z": -20.0},
            "rotate": {"x": 0.0, "y": 90.0, "z": 0.0},
            "near": 0.1, "far": 500.0, "FOVy": 60.0 },
"objects": [ { "mesh": "data/gltf/sponza/Sponza.gltf",
               "translate": {"x":0,"y":0,"z":0}, "rotate": {"x":0,"y":0,"z":0},
               "scale": {"x": 0.3, "y": 0.3, "z": 0.3} } ],
"lights": [ %s ]
}""" % ",\n".join(_SPONZA_LIGHT % (x, z) for x in (0.0, -60.0, 60.0) for z in (-40.0, 40.0))


# ------------------------------------------------------------------ stand-in meshes

def _box_arrays(low, high):
    """Flat-shaded box: 24 positions, normals and 36 indices (counter-clockwise)."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    positions, normals = [], []
    for axis in range(3):
        for sign in (1, -1):
            u_axis, v_axis = ((axis + 1) % 3, (axis + 2) % 3) if sign > 0 else \
                ((axis + 2) % 3, (axis + 1) % 3)
            base = low.copy()
            if sign > 0:
                base[axis] = high[axis]
            u, v = np.zeros(3), np.zeros(3)
            u[u_axis] = high[u_axis] - low[u_axis]
            v[v_axis] = high[v_axis] - low[v_axis]
            positions += [base, base + u, base + u + v, base + v]
            normal = np.zeros(3)
            normal[axis] = sign
            normals += [normal] * 4
    indices = np.array([[q * 4, q * 4 + 1, q * 4 + 2, q * 4, q * 4 + 2, q * 4 + 3]
                        for q in range(6)], dtype=np.uint16).reshape(-1)
    return np.array(positions, np.float32), np.array(normals, np.float32), indices


def _gltf_document(low, high, node, bin_uri):
    positions, normals, indices = _box_arrays(low, high)
    blob = positions.tobytes() + normals.tobytes() + indices.tobytes()
    document = {
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [dict(node, mesh=0)],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1},
                                    "indices": 2, "material": 0}]}],
        "materials": [{"name": "stand-in", "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.7, 0.6, 1.0]}}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 24, "type": "VEC3",
             "min": [float(v) for v in positions.min(0)],
             "max": [float(v) for v in positions.max(0)]},
            {"bufferView": 1, "componentType": 5126, "count": 24, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "count": 36, "type": "SCALAR"}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 288},
            {"buffer": 0, "byteOffset": 288, "byteLength": 288},
            {"buffer": 0, "byteOffset": 576, "byteLength": 72}],
        "buffers": [{"byteLength": len(blob)} if bin_uri is None
                    else {"uri": bin_uri, "byteLength": len(blob)}],
    }
    return document, blob


def write_box_gltf(path, low=(-1, 0, -1), high=(1, 1, 1), node=None):
    """A .gltf + .bin box stand-in; ``node`` holds glTF node transforms."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    bin_name = os.path.splitext(os.path.basename(path))[0] + ".bin"
    document, blob = _gltf_document(low, high, node or {"name": "box"}, bin_name)
    with open(path, "w") as stream:
        json.dump(document, stream)
    with open(os.path.join(os.path.dirname(path), bin_name), "wb") as stream:
        stream.write(blob)
    return path


def write_box_glb(path, low=(-1, 0, -1), high=(1, 1, 1)):
    document, blob = _gltf_document(low, high, {"name": "box"}, None)
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = (struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(blob), b"BIN\0") + blob)
    with open(path, "wb") as stream:
        stream.write(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


def _box_triangles(low, high):
    positions, _, indices = _box_arrays(low, high)
    return positions, indices.reshape(-1, 3)


def write_box_obj(path, low, high):
    positions, triangles = _box_triangles(low, high)
    lines = [f"v {x} {y} {z}" for x, y, z in positions]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    with open(path, "w") as stream:
        stream.write("\n".join(lines) + "\n")
    return path


def write_box_ply(path, low, high):
    positions, triangles = _box_triangles(low, high)
    header = ["ply", "format ascii 1.0", f"element vertex {len(positions)}",
              "property float x", "property float y", "property float z",
              f"element face {len(triangles)}", "property list uchar int vertex_indices",
              "end_header"]
    lines = header + [f"{x} {y} {z}" for x, y, z in positions]
    lines += [f"3 {a} {b} {c}" for a, b, c in triangles]
    with open(path, "w") as stream:
        stream.write("\n".join(lines) + "\n")
    return path


def write_box_stl(path, low, high):
    positions, triangles = _box_triangles(low, high)
    lines = ["solid box"]
    for triangle in triangles:
        a, b, c = positions[triangle]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        lines += [f"facet normal {n[0]} {n[1]} {n[2]}", "outer loop"]
        lines += [f"vertex {x} {y} {z}" for x, y, z in (a, b, c)]
        lines += ["endloop", "endfacet"]
    lines.append("endsolid box")
    with open(path, "w") as stream:
        stream.write("\n".join(lines) + "\n")
    return path


# --------------------------------------------------------------------------- helpers

@pytest.fixture
def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 1280, 720
    return scene


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A course-like project folder as the current directory."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def write_scene(folder, name, text):
    path = os.path.join(folder, name)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as stream:
        stream.write(text if isinstance(text, str) else json.dumps(text, indent=1))
    return path


def objects_of(collection, kind):
    return [obj for obj in collection.all_objects if obj.type == kind]


def world_bounds(objects):
    corners = []
    for obj in objects:
        world = np.array(obj.matrix_world)
        local = np.array([tuple(c) for c in obj.bound_box])
        corners.append(local @ world[:3, :3].T + world[:3, 3])
    corners = np.concatenate(corners)
    return corners.min(0), corners.max(0)


def assert_camera_sees_content(scene, collection):
    """The centre of the meshes' world bounds projects in front of the camera, in frame."""
    bpy.context.view_layer.update()
    low, high = world_bounds(objects_of(collection, 'MESH'))
    centre = (low + high) / 2
    x, y, depth = world_to_camera_view(scene, scene.camera, bpy_vector(centre))
    assert depth > scene.camera.data.clip_start, f"content centre is behind the camera ({depth})"
    assert depth < scene.camera.data.clip_end
    assert 0.0 <= x <= 1.0 and 0.0 <= y <= 1.0, f"content centre is out of frame ({x}, {y})"


def bpy_vector(values):
    import mathutils
    return mathutils.Vector([float(v) for v in values])


def fingerprint():
    """Names of everything an import could touch, plus camera, active collection, selection."""
    kinds = ("objects", "meshes", "materials", "images", "cameras", "lights", "collections",
             "node_groups", "textures", "actions", "worlds")
    view_layer = bpy.context.view_layer
    state = {kind: sorted(block.name for block in getattr(bpy.data, kind)) for kind in kinds}
    scene = bpy.context.scene
    state["scene.camera"] = scene.camera.name if scene.camera else None
    state["children"] = sorted(c.name for c in scene.collection.children)
    state["active collection"] = view_layer.active_layer_collection.name
    state["selected"] = sorted(o.name for o in view_layer.objects if o.select_get())
    state["active"] = view_layer.objects.active.name if view_layer.objects.active else None
    state["collection props"] = sorted(
        (c.name, c.get("csm_source"), c.get("csm_import_order")) for c in bpy.data.collections)
    return state


# --------------------------------------------------------------- committed scenes

def test_default_scene(scene):
    collection = scene_builder.import_scene_file(os.path.join(SCENES, "default.json"))
    assert collection.name == "default"
    assert collection.name in scene.collection.children
    assert collection["csm_source"] == os.path.join(SCENES, "default.json")
    assert [o.type for o in collection.all_objects].count('MESH') == 1
    assert sorted(o.type for o in collection.all_objects) == ['CAMERA', 'EMPTY', 'LIGHT', 'MESH']
    sun = objects_of(collection, 'LIGHT')[0]
    # The file's intensity 1 is pi W/m^2: Blender's Lambert divides by pi (docs/lighting.md).
    assert sun.data.type == 'SUN' and math.isclose(sun.data.energy, math.pi, rel_tol=1e-6)
    travel = np.array(sun.matrix_world.to_3x3()) @ (0, 0, -1)
    expected = C[:3, :3] @ (np.array([0.3, -0.6, -0.7]) / np.linalg.norm([0.3, -0.6, -0.7]))
    assert np.allclose(travel, expected, atol=1e-5)
    assert np.allclose(collection["csm_sun_direction"], expected, atol=1e-6)
    camera = scene.camera
    assert camera.name in collection.objects
    assert math.isclose(camera.data.angle_y, math.radians(30), rel_tol=1e-5)
    assert camera.data.sensor_fit == 'VERTICAL'
    assert math.isclose(camera.data.clip_start, 0.1, rel_tol=1e-5)
    assert math.isclose(camera.data.clip_end, 500.0, rel_tol=1e-5)
    assert np.allclose(np.array(camera.matrix_world),
                       conventions.camera_world_matrix_zup((-190, 40, 50), (0, 100, 0)), atol=1e-4)
    # The landscape at scale 100 spans about 386 x 386 units and 66 high (Blender Z).
    low, high = world_bounds(objects_of(collection, 'MESH'))
    assert np.allclose(low, (-193, -193, 0), atol=0.5) and np.allclose(high, (193, 193, 66), atol=1)
    material = objects_of(collection, 'MESH')[0].material_slots[0].material
    assert any(node.type == 'TEX_IMAGE' and node.image is not None
               for node in material.node_tree.nodes)
    assert_camera_sees_content(scene, collection)


def test_shadow_test_scene(scene):
    collection = scene_builder.import_scene_file(os.path.join(SCENES, "shadow_test.json"))
    meshes = objects_of(collection, 'MESH')
    assert len(meshes) == 40 and len(collection.all_objects) == 43
    pillars = sorted((o for o in meshes if o.name.startswith("pillar")),
                     key=lambda o: o.matrix_world.translation.x)
    assert len(pillars) == 39
    xs = [o.matrix_world.translation.x for o in pillars]
    assert np.allclose(np.diff(xs), 5.0)
    for pillar in pillars:
        low, high = world_bounds([pillar])
        assert np.allclose(high - low, (1, 1, 3), atol=1e-5)   # file (1,3,1) is tall in Blender Z
        assert math.isclose(low[2], 0.0, abs_tol=1e-5)
    assert [o.data.type for o in objects_of(collection, 'LIGHT')] == ['SUN']
    assert_camera_sees_content(scene, collection)


def test_point_lights_scene(scene):
    path = os.path.join(SCENES, "point_lights.json")
    with open(path) as stream:
        document = json.load(stream)
    collection = scene_builder.import_scene_file(path)
    points = sorted((o for o in objects_of(collection, 'LIGHT') if o.data.type == 'POINT'),
                    key=lambda o: int(o.name.split()[-1]))
    assert len(points) == 6
    for obj, light in zip(points, document["lights"]):
        position = np.array([light["position"][a] for a in "xyz"])
        assert np.allclose(obj.location, C[:3, :3] @ position, atol=1e-4)
        assert np.allclose(obj.data.color, [light["color"][a] for a in "xyz"], atol=1e-6)
        assert math.isclose(obj.data.energy, 100.0)
        assert obj.data["csm_radius"] == 30
        assert obj.data.use_custom_distance and math.isclose(obj.data.cutoff_distance, 30)
    suns = [o for o in objects_of(collection, 'LIGHT') if o.data.type == 'SUN']
    assert len(suns) == 1 and max(suns[0].data.color) < 0.2
    assert_camera_sees_content(scene, collection)


# ------------------------------------------------------------ samples from the doc

def test_scene_shadow_verbatim_with_course_paths(scene, workdir):
    write_box_gltf(str(workdir / "data/gltf/vokselia/vokselia.gltf"),
                   (-1.93, 0, -1.93), (1.93, 0.66, 1.93))
    path = write_scene(str(workdir), "data/scenes/sceneShadow.json", SCENE_SHADOW)
    collection = scene_builder.import_scene_file(path)
    low, high = world_bounds(objects_of(collection, 'MESH'))
    assert np.allclose(low, (-193, -193, 0), atol=1e-3) and np.allclose(high, (193, 193, 66),
                                                                      atol=1e-3)
    assert_camera_sees_content(scene, collection)


def test_course_paths_resolve_from_any_folder_via_the_scene_ancestors(scene, workdir,
                                                                      monkeypatch):
    write_box_gltf(str(workdir / "project/data/gltf/vokselia/vokselia.gltf"))
    path = write_scene(str(workdir), "project/data/scenes/sceneShadow.json", SCENE_SHADOW)
    elsewhere = workdir / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    collection = scene_builder.import_scene_file(path)
    assert len(objects_of(collection, 'MESH')) == 1


def test_sponza_sample_keeps_the_gltf_node_scale(scene, workdir):
    # The real Sponza.gltf has a node with scale 0.3; with the scene's 0.3 it is 0.09.
    write_box_gltf(str(workdir / "data/gltf/sponza/Sponza.gltf"), (-1100, 0, -450),
                   (1100, 780, 450), node={"name": "sponza", "scale": [0.3, 0.3, 0.3]})
    path = write_scene(str(workdir), "data/scenes/assignment1.json", SPONZA)
    collection = scene_builder.import_scene_file(path)
    mesh = objects_of(collection, 'MESH')[0]
    assert np.allclose(mesh.matrix_world.to_scale(), (0.09, 0.09, 0.09), atol=1e-6)
    low, high = world_bounds([mesh])
    assert np.allclose(high - low, (2200 * 0.09, 900 * 0.09, 780 * 0.09), atol=1e-3)
    points = [o for o in objects_of(collection, 'LIGHT') if o.data.type == 'POINT']
    assert len(points) == 6 and not [o for o in objects_of(collection, 'LIGHT')
                                     if o.data.type == 'SUN']
    assert all(np.allclose(o.data.color, (1.0, 0.95, 0.65)) for o in points)
    assert math.isclose(scene.camera.data.angle_y, math.radians(60), rel_tol=1e-5)
    assert_camera_sees_content(scene, collection)


def test_translation_variant(scene, workdir):
    write_box_gltf(str(workdir / "data/gltf/vokselia/vokselia.gltf"))
    text = SCENE_SHADOW.replace('"translate": { "x": 0.0', '"translation": { "x": 25.0')
    assert text != SCENE_SHADOW
    collection = scene_builder.import_scene_file(write_scene(str(workdir), "t.json", text))
    parent = objects_of(collection, 'EMPTY')[0]
    assert np.allclose(parent.matrix_world.translation, (25, 0, 0))
    assert_camera_sees_content(scene, collection)


def test_no_lights_and_no_directional_light(scene, workdir):
    write_box_gltf(str(workdir / "data/gltf/vokselia/vokselia.gltf"))
    document = json.loads(SCENE_SHADOW)
    del document["lights"]
    del document["directional_light"]
    collection = scene_builder.import_scene_file(write_scene(str(workdir), "dark.json", document))
    assert objects_of(collection, 'LIGHT') == []
    assert "csm_sun_direction" not in collection
    assert_camera_sees_content(scene, collection)


def test_no_camera_makes_a_default_view_of_the_content(scene, workdir):
    write_box_gltf(str(workdir / "data/gltf/vokselia/vokselia.gltf"),
                   (-1.93, 0, -1.93), (1.93, 0.66, 1.93))
    document = json.loads(SCENE_SHADOW)
    del document["camera"]
    document["objects"][0]["translate"] = {"x": 500, "y": 10, "z": -300}
    collection = scene_builder.import_scene_file(write_scene(str(workdir), "nocam.json", document))
    cameras = objects_of(collection, 'CAMERA')
    assert len(cameras) == 1 and scene.camera == cameras[0]
    assert_camera_sees_content(scene, collection)
    # The whole box is in frame, not only its centre.
    low, high = world_bounds(objects_of(collection, 'MESH'))
    for corner in np.array(np.meshgrid(*zip(low, high))).T.reshape(-1, 3):
        x, y, depth = world_to_camera_view(scene, scene.camera, bpy_vector(corner))
        assert 0 <= x <= 1 and 0 <= y <= 1
        assert scene.camera.data.clip_start < depth < scene.camera.data.clip_end


def test_import_into_a_scene_that_is_not_the_active_one(scene):
    other = bpy.data.scenes.new("Other")
    collection = scene_builder.import_scene_file(os.path.join(SCENES, "shadow_test.json"), other)
    assert collection.name in other.collection.children
    assert collection.name not in scene.collection.children
    assert len(other.objects) == 43 and len(scene.objects) == 0
    assert other.camera is not None and scene.camera is None


# ----------------------------------------------------------------- transforms

def test_object_transform_and_node_transform_compose_like_the_file(scene, workdir):
    node = {"translation": [1.0, 2.0, 3.0], "rotation": [0.0, 0.38268343, 0.0, 0.92387953],
            "scale": [1.0, 2.0, 0.5]}
    write_box_gltf(str(workdir / "m.gltf"), (0, 0, 0), (1, 1, 1), node=node)
    placement = {"translate": {"x": 10, "y": -4, "z": 7}, "rotate": {"x": 30, "y": -50, "z": 20},
                 "scale": {"x": 2, "y": -1.5, "z": 3}}
    document = {"objects": [dict(mesh="m.gltf", **placement)]}
    collection = scene_builder.import_scene_file(write_scene(str(workdir), "s.json", document))
    bpy.context.view_layer.update()
    parent = objects_of(collection, 'EMPTY')[0]
    values = [[placement[k][a] for a in "xyz"] for k in ("translate", "rotate", "scale")]
    assert np.allclose(np.array(parent.matrix_world), conventions.object_matrix_zup(*values),
                       atol=1e-4)
    # Where a vertex of the file ends up: file world = M_object * M_node * v, then C.
    half = math.radians(45) / 2
    node_matrix = (conventions.translation((1, 2, 3)) @ conventions.rotation_y(45)
                   @ conventions.scaling((1, 2, 0.5)))
    assert math.isclose(math.sin(half), 0.38268343, rel_tol=1e-6)
    file_corner = conventions.object_matrix_yup(*values) @ node_matrix @ (1, 1, 1, 1)
    mesh = objects_of(collection, 'MESH')[0]
    world = np.array(mesh.matrix_world)
    vertices = np.array([tuple(v.co) + (1.0,) for v in mesh.data.vertices]) @ world.T
    distances = np.linalg.norm(vertices[:, :3] - (C @ file_corner)[:3], axis=1)
    assert distances.min() < 1e-3


@pytest.mark.parametrize("extension, writer", [
    (".obj", write_box_obj), (".ply", write_box_ply), (".stl", write_box_stl),
    (".glb", write_box_glb)])
def test_every_mesh_type_is_read_as_y_up(scene, workdir, extension, writer):
    # A column 3 high along file +Y must stand 3 high along Blender +Z.
    writer(str(workdir / f"column{extension}"), (-0.5, 0, -0.5), (0.5, 3, 0.5))
    document = {"objects": [{"mesh": f"column{extension}", "translate": {"x": 4, "y": 0, "z": 0}}]}
    collection = scene_builder.import_scene_file(write_scene(str(workdir), "s.json", document))
    bpy.context.view_layer.update()
    meshes = objects_of(collection, 'MESH')
    assert len(meshes) == 1
    low, high = world_bounds(meshes)
    assert np.allclose(low, (3.5, -0.5, 0), atol=1e-4) and np.allclose(high, (4.5, 0.5, 3),
                                                                       atol=1e-4)


# ----------------------------------------------------------------- re-import

def test_reimport_replaces_the_previous_import(scene, workdir):
    def counts():
        return {kind: len(getattr(bpy.data, kind)) for kind in
                ("objects", "meshes", "materials", "images", "cameras", "lights", "collections",
                 "node_groups", "textures", "worlds")}

    path = os.path.join(SCENES, "default.json")
    first = scene_builder.import_scene_file(path)
    first_names = sorted(o.name for o in first.all_objects)
    before = counts()
    second = scene_builder.import_scene_file(path)
    assert counts() == before
    assert [c.name for c in scene.collection.children] == ["default"]
    assert sorted(o.name for o in second.all_objects) == first_names   # no ".001" names
    assert scene.camera.name in second.objects
    assert second["csm_import_order"] == 2


def test_reimport_keeps_other_imports_and_user_objects(scene):
    user = bpy.data.objects.new("user empty", None)
    scene.collection.objects.link(user)
    scene_builder.import_scene_file(os.path.join(SCENES, "shadow_test.json"))
    scene_builder.import_scene_file(os.path.join(SCENES, "default.json"))
    scene_builder.import_scene_file(os.path.join(SCENES, "shadow_test.json"))
    assert sorted(c.name for c in scene.collection.children) == ["default", "shadow_test"]
    assert "user empty" in bpy.data.objects
    assert len(bpy.data.objects) == 1 + 43 + 4


def test_reload_reads_the_changed_file(scene, workdir):
    write_box_gltf(str(workdir / "data/gltf/vokselia/vokselia.gltf"))
    path = write_scene(str(workdir), "scene.json", SCENE_SHADOW)
    collection = scene_builder.import_scene_file(path)
    with open(path, "w") as stream:
        stream.write(SCENE_SHADOW.replace('"x": -190.0', '"x": -150.0'))
    reloaded = scene_builder.reload_scene(collection)
    assert np.allclose(scene.camera.matrix_world.translation, (-150, -50, 40), atol=1e-4)
    assert [c.name for c in scene.collection.children] == [reloaded.name]


def test_reload_of_a_plain_collection_is_an_error(scene):
    plain = bpy.data.collections.new("mine")
    with pytest.raises(SceneImportError, match="mine"):
        scene_builder.reload_scene(plain)


# -------------------------------------------------------------------- bad files

def _bad_cases(root):
    """(name, scene file path, words the message must contain)."""
    root = str(root)
    write_box_gltf(os.path.join(root, "data/gltf/vokselia/vokselia.gltf"))
    good = json.loads(SCENE_SHADOW)

    def variant(name, change):
        document = json.loads(json.dumps(good))
        change(document)
        return write_scene(root, name, document)

    cases = [
        ("invalid JSON", write_scene(root, "invalid.json", SCENE_SHADOW[:300]),
         ["invalid.json", "invalid JSON at line"]),
        ("wrong type", variant("wrongtype.json",
                               lambda d: d["objects"][0]["scale"].__setitem__("y", "big")),
         ["wrongtype.json", "objects[0].scale.y"]),
        ("NaN", write_scene(root, "nan.json", SCENE_SHADOW.replace('"far": 500.0', '"far": NaN')),
         ["nan.json", "camera.far", "NaN"]),
        ("zero direction", variant("zerodir.json", lambda d: d["directional_light"].__setitem__(
            "direction", {"x": 0, "y": 0, "z": 0})),
         ["zerodir.json", "directional_light.direction", "zero length"]),
        ("missing mesh", variant("missing.json", lambda d: d["objects"][0].__setitem__(
            "mesh", "data/gltf/gone/gone.gltf")),
         ["missing.json", "objects[0].mesh", "gone.gltf", "not found", "tried"]),
        ("unsupported extension", variant("fbx.json", lambda d: d["objects"][0].__setitem__(
            "mesh", "data/gltf/model.fbx")),
         ["fbx.json", "objects[0].mesh", "unsupported mesh type"]),
    ]
    folder = os.path.join(root, "folder.json")
    os.makedirs(folder)
    cases.append(("unreadable: a folder", folder, ["folder.json", "is a folder"]))
    binary = os.path.join(root, "binary.json")
    with open(binary, "wb") as stream:
        stream.write(b"\x89PNG\r\n\x1a\n\xff\xfe\x00")
    cases.append(("unreadable: not text", binary, ["binary.json", "not a UTF-8 text file"]))
    cases.append(("no such file", os.path.join(root, "nothere.json"),
                  ["nothere.json", "file not found"]))
    # A mesh missing its .bin buffer is found before anything is created.
    nobin = write_box_gltf(os.path.join(root, "nobin/nobin.gltf"))
    os.remove(os.path.join(root, "nobin/nobin.bin"))
    cases.append(("missing buffer", variant("nobin.json", lambda d: d["objects"][0].__setitem__(
        "mesh", nobin)), ["nobin.json", "objects[0].mesh", "nobin.bin"]))
    # A corrupt glTF that passes every check, so Blender's importer itself fails, after
    # the first object of the scene has already been imported.
    corrupt = write_box_gltf(os.path.join(root, "corrupt/corrupt.gltf"))
    with open(corrupt) as stream:
        document = json.load(stream)
    document["meshes"][0]["primitives"][0]["indices"] = 99
    with open(corrupt, "w") as stream:
        json.dump(document, stream)

    def two_objects(d):
        d["objects"].append(dict(d["objects"][0], mesh=corrupt))
    cases.append(("importer fails", variant("corrupt.json", two_objects),
                  ["corrupt.json", "objects[1].mesh", "corrupt.gltf", "glTF importer"]))
    return cases


def _prepared_scene(scene):
    """A scene with things an import could disturb: a user object and camera, an import."""
    scene_builder.import_scene_file(os.path.join(SCENES, "shadow_test.json"))
    user_camera = bpy.data.objects.new("user camera", bpy.data.cameras.new("user camera"))
    scene.collection.objects.link(user_camera)
    scene.camera = user_camera
    user_collection = bpy.data.collections.new("user stuff")
    scene.collection.children.link(user_collection)
    view_layer = bpy.context.view_layer
    view_layer.active_layer_collection = view_layer.layer_collection.children["user stuff"]
    for obj in view_layer.objects:
        obj.select_set(obj.name.startswith("pillar_0"))
    view_layer.objects.active = bpy.data.objects["pillar_03"]


def test_every_bad_file_gives_one_message_and_changes_nothing(scene, workdir):
    _prepared_scene(scene)
    for name, path, words in _bad_cases(workdir):
        before = fingerprint()
        with pytest.raises(SceneImportError) as info:
            scene_builder.import_scene_file(path)
        message = str(info.value)
        assert "\n" not in message and "Traceback" not in message, (name, message)
        for word in words:
            assert word in message, (name, word, message)
        assert fingerprint() == before, name


def test_failed_reimport_keeps_the_previous_import(scene, workdir):
    write_box_gltf(str(workdir / "data/gltf/vokselia/vokselia.gltf"))
    path = write_scene(str(workdir), "scene.json", SCENE_SHADOW)
    scene_builder.import_scene_file(path)
    before = fingerprint()
    with open(path, "w") as stream:
        stream.write(SCENE_SHADOW.replace('"FOVy": 30.0', '"FOVy": "wide"'))
    with pytest.raises(SceneImportError, match=r"camera\.FOVy"):
        scene_builder.import_scene_file(path)
    # Now the importer itself fails, after the new collection has been started.
    gltf_path = str(workdir / "data/gltf/vokselia/vokselia.gltf")
    with open(gltf_path) as stream:
        document = json.load(stream)
    document["meshes"][0]["primitives"][0]["indices"] = 99
    with open(gltf_path, "w") as stream:
        json.dump(document, stream)
    with open(path, "w") as stream:
        stream.write(SCENE_SHADOW)
    with pytest.raises(SceneImportError, match="vokselia.gltf"):
        scene_builder.import_scene_file(path)
    assert fingerprint() == before


# --------------------------------------------------------------------- operators

@pytest.fixture
def operators_registered():
    from csm_engine.blender import operators
    if not hasattr(bpy.types, "CSM_OT_import_scene"):
        operators.register()
    return operators


class _Reports:
    def __init__(self):
        self.reports = []

    def report(self, kind, message):
        self.reports.append((set(kind), message))


def test_import_operator_reports_errors_and_cancels(scene, workdir, operators_registered):
    bad = write_scene(str(workdir), "bad.json", '{"objects": [ {"mesh": 3} ]}')
    before = fingerprint()
    # Blender turns an ERROR report of a bpy.ops call into a RuntimeError holding only the
    # report text; in the UI the same text is shown in the status bar.
    with pytest.raises(RuntimeError) as info:
        bpy.ops.csm.import_scene(filepath=bad)
    assert str(info.value).strip() == \
        f"Error: {bad}: objects[0].mesh: expected a file path string, got a number 3"
    assert fingerprint() == before
    # The operator itself returns CANCELLED with that one report.
    operator = _Reports()
    operator.filepath = bad
    operator.mode = 'REPLACE'
    result = operators_registered.CSM_OT_import_scene.execute(operator, bpy.context)
    assert result == {'CANCELLED'}
    assert operator.reports == [({'ERROR'}, str(info.value).strip()[len("Error: "):])]
    assert fingerprint() == before


def test_import_and_reload_operators(scene, operators_registered):
    assert bpy.ops.csm.import_scene(filepath=os.path.join(SCENES, "shadow_test.json"),
                                    mode='ADD') == {'FINISHED'}
    assert bpy.ops.csm.import_scene(filepath=os.path.join(SCENES, "default.json"),
                                    mode='ADD') == {'FINISHED'}
    # The active object belongs to shadow_test: that is the import to reload.
    bpy.context.view_layer.objects.active = bpy.data.objects["pillar_10"]
    assert bpy.ops.csm.reload_scene() == {'FINISHED'}
    assert bpy.data.collections["shadow_test"]["csm_import_order"] == 3
    assert bpy.data.collections["default"]["csm_import_order"] == 2
    bpy.context.view_layer.objects.active = bpy.data.objects["voxel_landscape"]
    assert bpy.ops.csm.reload_scene() == {'FINISHED'}
    assert bpy.data.collections["default"]["csm_import_order"] == 4
    # Without an active object, the most recent import (default) is reloaded.
    bpy.context.view_layer.objects.active = None
    assert bpy.ops.csm.reload_scene() == {'FINISHED'}
    assert bpy.data.collections["default"]["csm_import_order"] == 5
    assert bpy.data.collections["shadow_test"]["csm_import_order"] == 3


def test_import_menu_entry(operators_registered):
    from csm_engine.blender import operators
    drawers = getattr(bpy.types.TOPBAR_MT_file_import, "_dyn_ui_initialize")()
    assert operators.menu_import in drawers
