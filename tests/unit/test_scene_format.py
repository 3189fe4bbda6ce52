"""Scene file parsing: every documented variant loads; every mistake is one clear line."""

import json
import os

import pytest

from csm_engine.core import scene_format
from csm_engine.core.scene_format import SceneFormatError, parse_scene

from tests.conftest import REPO

# The course's official CSM scene, verbatim from scene-format.md.
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

# The assignment-1 sample as written in the doc (abridged there; wrapped in braces here),
# with the real file's duplicated "x" inside a colour.
SPONZA = """{
"camera": { "translate": {"x": -90.0, "y": 40.0, "z": -20.0},
            "rotate": {"x": 0.0, "y": 90.0, "z": 0.0},
            "near": 0.1, "far": 500.0, "FOVy": 60.0 },
"objects": [ { "mesh": "data/gltf/sponza/Sponza.gltf",
               "translate": {"x":0,"y":0,"z":0}, "rotate": {"x":0,"y":0,"z":0},
               "scale": {"x": 0.3, "y": 0.3, "z": 0.3} } ],
"lights": [ { "position": {"x": 0.0, "y": 60.0, "z": -40.0},
              "color": {"x": 1.0, "x": 1.0, "y": 0.95, "z": 0.65},
              "radius": 30 } ]
}"""


def parse(document, source="scene.json"):
    text = document if isinstance(document, str) else json.dumps(document)
    return parse_scene(text, source)


def base():
    return json.loads(SCENE_SHADOW)


def error_for(document, source="scene.json"):
    with pytest.raises(SceneFormatError) as info:
        parse(document, source)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(source + ": ")
    return message


# ------------------------------------------------------------------ documented variants

def test_scene_shadow_verbatim():
    scene = parse(SCENE_SHADOW)
    assert scene.camera.translate.as_tuple() == (-190.0, 40.0, 50.0)
    assert scene.camera.rotate.as_tuple() == (0.0, 100.0, 0.0)
    assert (scene.camera.near, scene.camera.far, scene.camera.fov_y_degrees) == (0.1, 500.0, 30.0)
    assert len(scene.objects) == 1
    assert scene.objects[0].mesh == "data/gltf/vokselia/vokselia.gltf"
    assert scene.objects[0].scale.as_tuple() == (100.0, 100.0, 100.0)
    assert scene.lights == []
    assert scene.directional_light.direction.as_tuple() == (0.3, -0.6, -0.7)
    assert scene.directional_light.color.as_tuple() == (1.0, 1.0, 1.0)


def test_sponza_sample_with_duplicated_key():
    scene = parse(SPONZA)
    assert scene.directional_light is None
    assert scene.lights[0].color.as_tuple() == (1.0, 0.95, 0.65)
    assert scene.lights[0].radius == 30.0
    assert scene.lights[0].position.as_tuple() == (0.0, 60.0, -40.0)
    assert scene.camera.rotate.y == 90.0


def test_duplicated_key_last_one_wins():
    text = SPONZA.replace('"x": 1.0, "x": 1.0', '"x": 0.2, "x": 0.9')
    assert parse(text).lights[0].color.x == 0.9


def test_translation_is_an_old_spelling_of_translate():
    document = base()
    document["objects"][0]["translation"] = document["objects"][0].pop("translate")
    document["objects"][0]["translation"]["x"] = 12.5
    document["camera"]["translation"] = document["camera"].pop("translate")
    scene = parse(document)
    assert scene.objects[0].translate.x == 12.5
    assert scene.camera.translate.as_tuple() == (-190.0, 40.0, 50.0)


@pytest.mark.parametrize("lights", ["missing", None, []])
def test_missing_null_or_empty_lights(lights):
    document = base()
    if lights == "missing":
        del document["lights"]
    else:
        document["lights"] = lights
    assert parse(document).lights == []


def test_no_directional_light_means_no_sun():
    document = base()
    del document["directional_light"]
    assert parse(document).directional_light is None


def test_no_camera_is_allowed():
    document = base()
    del document["camera"]
    assert parse(document).camera is None


def test_optional_transform_parts_default_to_identity_and_extra_keys_are_ignored():
    document = {"objects": [{"mesh": "a.obj", "comment": "hi"}], "ambient": 0.02,
                "lights": [{"position": {"x": 1, "y": 2, "z": 3}, "radius": 5,
                            "intensity": 9}]}
    scene = parse(document)
    item = scene.objects[0]
    assert (item.translate.as_tuple(), item.rotate.as_tuple(), item.scale.as_tuple()) == \
        ((0, 0, 0), (0, 0, 0), (1, 1, 1))
    assert scene.lights[0].color.as_tuple() == (1, 1, 1)


def test_negative_scale_is_a_mirror_and_allowed():
    document = base()
    document["objects"][0]["scale"]["x"] = -2
    assert parse(document).objects[0].scale.x == -2.0


@pytest.mark.parametrize("mesh", ["a.gltf", "b.GLB", "c.obj", "d.ply", "e.STL"])
def test_supported_mesh_types(mesh):
    assert parse({"objects": [{"mesh": mesh}]}).objects[0].mesh == mesh


def test_the_committed_scenes_parse():
    for name in ("default", "shadow_test", "point_lights"):
        scene = scene_format.load_scene(os.path.join(REPO, "csm_engine", "data", "scenes", name + ".json"))
        assert scene.objects and scene.camera is not None


# --------------------------------------------------------------------------- errors

def test_invalid_json_names_line_and_column():
    text = '{\n  "objects": [\n    {"mesh": "a.obj" "scale": 1}\n  ]\n}'
    message = error_for(text, "broken.json")
    assert "line 3, column 22" in message
    assert "invalid JSON" in message


def test_truncated_file():
    message = error_for(SCENE_SHADOW[:200], "cut.json")
    assert "invalid JSON at line" in message


def test_top_level_must_be_an_object():
    assert "must be a JSON object" in error_for("[1, 2]")


def test_objects_is_required():
    assert "objects: missing" in error_for({"lights": []})


@pytest.mark.parametrize("mutate, path", [
    (lambda d: d["objects"][0]["scale"].__setitem__("y", "big"), "objects[0].scale.y"),
    (lambda d: d["objects"][0].__setitem__("scale", [1, 2, 3]), "objects[0].scale"),
    (lambda d: d["objects"][0]["scale"].pop("z"), "objects[0].scale.z"),
    (lambda d: d["objects"][0].__setitem__("mesh", 3), "objects[0].mesh"),
    (lambda d: d["objects"][0].pop("mesh"), "objects[0].mesh"),
    (lambda d: d.__setitem__("objects", {"a": 1}), "objects"),
    (lambda d: d.__setitem__("lights", "none"), "lights"),
    (lambda d: d.__setitem__("lights", [1]), "lights[0]"),
    (lambda d: d["camera"].__setitem__("FOVy", True), "camera.FOVy"),
    (lambda d: d["camera"].pop("near"), "camera.near"),
    (lambda d: d["directional_light"]["color"].__setitem__("x", None), "directional_light.color.x"),
    (lambda d: d.__setitem__("camera", 5), "camera"),
])
def test_wrong_types_name_their_json_path(mutate, path):
    document = base()
    mutate(document)
    message = error_for(document)
    assert f": {path}: " in message


def test_the_third_object_is_named_by_index():
    document = base()
    document["objects"] = [dict(document["objects"][0]) for _ in range(3)]
    document["objects"][2] = json.loads(json.dumps(document["objects"][2]))
    document["objects"][2]["scale"]["y"] = "tall"
    message = error_for(document)
    assert "objects[2].scale.y" in message and '"tall"' in message


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e999"])
def test_non_finite_numbers_are_refused_with_their_path(literal):
    text = SCENE_SHADOW.replace('"y": 100, "z": 100', f'"y": {literal}, "z": 100')
    assert text != SCENE_SHADOW
    message = error_for(text)
    assert "objects[0].scale.y" in message
    assert "finite" in message


def test_nan_in_an_ignored_key_is_harmless():
    text = SCENE_SHADOW.replace('"lights": []', '"lights": [], "exposure": NaN')
    assert parse(text).lights == []


def test_huge_integer_is_refused():
    document = base()
    document["camera"]["far"] = 10 ** 400
    assert "camera.far" in error_for(document)


@pytest.mark.parametrize("mutate, path, words", [
    (lambda d: d["directional_light"].__setitem__("direction", {"x": 0, "y": 0, "z": 0.0}),
     "directional_light.direction", "zero length"),
    (lambda d: d["objects"][0]["scale"].__setitem__("x", 0), "objects[0].scale.x", "zero"),
    (lambda d: d["camera"].__setitem__("near", 0), "camera.near", "greater than 0"),
    (lambda d: d["camera"].__setitem__("near", -1), "camera.near", "greater than 0"),
    (lambda d: d["camera"].__setitem__("far", 0.1), "camera.far", "greater than near"),
    (lambda d: d["camera"].__setitem__("FOVy", 0), "camera.FOVy", "between 0 and 180"),
    (lambda d: d["camera"].__setitem__("FOVy", 180), "camera.FOVy", "between 0 and 180"),
    (lambda d: d["directional_light"]["color"].__setitem__("y", -0.5),
     "directional_light.color.y", "negative"),
    (lambda d: d.__setitem__("lights", [{"position": {"x": 0, "y": 0, "z": 0}, "radius": 0}]),
     "lights[0].radius", "greater than 0"),
    (lambda d: d["objects"][0].__setitem__("mesh", "data/model.fbx"), "objects[0].mesh",
     "unsupported mesh type"),
    (lambda d: d["objects"][0].__setitem__("mesh", "data/model"), "objects[0].mesh",
     "unsupported mesh type"),
    (lambda d: d["objects"][0].__setitem__("mesh", "  "), "objects[0].mesh", "empty"),
])
def test_bad_values_name_their_path(mutate, path, words):
    document = base()
    mutate(document)
    message = error_for(document)
    assert f": {path}: " in message
    assert words in message


def test_messages_stay_on_one_line_and_short():
    document = base()
    document["objects"][0]["mesh"] = "line one\nline two " + "x" * 500 + ".fbx"
    message = error_for(document)
    assert len(message) < 200


def test_error_is_a_value_error_with_parts():
    with pytest.raises(ValueError) as info:
        parse({"objects": 1}, "f.json")
    assert info.value.source == "f.json" and info.value.path == "objects"


# --------------------------------------------------------------------------- files

def test_load_scene_reads_utf8_with_bom(tmp_path):
    path = tmp_path / "bom.json"
    path.write_bytes(b"\xef\xbb\xbf" + SCENE_SHADOW.encode())
    assert scene_format.load_scene(path).source == str(path)


@pytest.mark.parametrize("make, words", [
    (lambda p: None, "file not found"),
    (lambda p: p.mkdir(), "is a folder"),
    (lambda p: p.write_bytes(b'{"objects": [\xff\xfe]}'), "not a UTF-8 text file"),
])
def test_load_scene_errors_name_the_file(tmp_path, make, words):
    path = tmp_path / "scene.json"
    make(path)
    with pytest.raises(SceneFormatError) as info:
        scene_format.load_scene(path)
    assert str(info.value).startswith(str(path) + ": ")
    assert words in str(info.value)


def test_load_scene_unreadable_file(tmp_path, monkeypatch):
    path = tmp_path / "locked.json"
    path.write_text(SCENE_SHADOW)
    path.chmod(0)
    if os.access(path, os.R_OK):   # running as root: make the read itself fail
        def denied(*args, **kwargs):
            raise PermissionError(13, "Permission denied")
        monkeypatch.setattr(scene_format, "open", denied, raising=False)
    try:
        with pytest.raises(SceneFormatError) as info:
            scene_format.load_scene(path)
    finally:
        path.chmod(0o644)
    assert str(path) in str(info.value) and "permission denied" in str(info.value)


# --------------------------------------------------------------------- mesh lookup

@pytest.fixture
def project(tmp_path):
    """A course-like tree: project/data/scenes/s.json, meshes under project/data/gltf."""
    scenes = tmp_path / "project" / "data" / "scenes"
    scenes.mkdir(parents=True)
    (tmp_path / "project" / "data" / "gltf").mkdir()
    (tmp_path / "elsewhere").mkdir()
    scene = scenes / "s.json"
    scene.write_text("{}")
    return tmp_path, scene


def test_mesh_next_to_the_scene_comes_first(project):
    root, scene = project
    (scene.parent / "m.obj").write_text("v 0 0 0")
    (root / "elsewhere" / "m.obj").write_text("v 0 0 0")
    found = scene_format.resolve_mesh_path("m.obj", scene, cwd=root / "elsewhere")
    assert found == str(scene.parent / "m.obj")


def test_mesh_relative_to_the_current_folder(project):
    root, scene = project
    (root / "elsewhere" / "m.obj").write_text("v 0 0 0")
    found = scene_format.resolve_mesh_path("m.obj", scene, cwd=root / "elsewhere")
    assert found == str(root / "elsewhere" / "m.obj")


def test_course_paths_resolve_through_the_scene_folders_ancestors(project):
    root, scene = project
    mesh = root / "project" / "data" / "gltf" / "m.gltf"
    mesh.write_text("{}")
    found = scene_format.resolve_mesh_path("data/gltf/m.gltf", scene, cwd=root / "elsewhere")
    assert found == str(mesh)
    # Windows-style separators in a course file
    assert scene_format.resolve_mesh_path("data\\gltf\\m.gltf", scene, cwd=root) == str(mesh)


def test_missing_mesh_lists_every_path_tried(project):
    root, scene = project
    with pytest.raises(SceneFormatError) as info:
        scene_format.resolve_mesh_path("data/gltf/gone.gltf", scene, cwd=root / "elsewhere",
                                       json_path="objects[0].mesh")
    message = str(info.value)
    tried = scene_format.mesh_path_candidates("data/gltf/gone.gltf", scene, root / "elsewhere")
    assert tried[0] == str(scene.parent / "data" / "gltf" / "gone.gltf")
    assert tried[1] == str(root / "elsewhere" / "data" / "gltf" / "gone.gltf")
    assert str(root / "project" / "data" / "gltf" / "gone.gltf") in tried
    assert len(tried) == len(set(tried))
    for candidate in tried:
        assert candidate in message
    assert "objects[0].mesh" in message and "\n" not in message


def test_absolute_mesh_path_is_used_as_is(project):
    root, scene = project
    mesh = root / "elsewhere" / "abs.stl"
    mesh.write_text("solid x")
    assert scene_format.resolve_mesh_path(str(mesh), scene, cwd=root) == str(mesh)


def test_a_folder_is_not_a_mesh(project):
    root, scene = project
    (scene.parent / "dir.obj").mkdir()
    with pytest.raises(SceneFormatError):
        scene_format.resolve_mesh_path("dir.obj", scene, cwd=scene.parent)



@pytest.mark.parametrize("fov", [179.9999999, 1e-300, 172.9, 0.3])
def test_a_field_of_view_past_blenders_camera_is_refused_by_name(fov):
    text = ('{"camera": {"translate": {"x": 0, "y": 0, "z": 0}, "rotate": {"x": 0, "y": 0, '
            '"z": 0}, "near": 0.1, "far": 100, "FOVy": %r}, "objects": []}' % fov)
    with pytest.raises(SceneFormatError) as failure:
        parse_scene(text, "wide.json")
    message = str(failure.value)
    assert "camera.FOVy" in message and "Blender camera" in message, message
