"""A scene reads only its own folder tree by default (pip bpy, in process): a mesh path,
an OBJ's material library, an MTL texture or a glTF URI that resolves outside the scene's
folder (and the mesh file's own folder) is refused with one line before any importer
runs, leaving the scene as it was; the Allowed Folders preference and the CLI's
--allow-folder let the user name other folders.
"""

import json
import os

import bpy
import pytest

from csm_engine.blender import cli, preferences, scene_builder
from csm_engine.core import paths
from csm_engine.blender.scene_builder import SceneImportError

from tests.bpy.addon.test_cli import run_cli
from tests.bpy.addon.test_scene_import import (
    fingerprint, write_box_gltf, write_box_obj, write_scene)


@pytest.fixture
def scene(tmp_path, monkeypatch):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("CSM_DEBUG", raising=False)
    return bpy.context.scene


@pytest.fixture
def allowed_folders_preference(scene):
    """Set the preference with ``choose(text)``; cleared afterwards."""
    prefs = preferences.addon_preferences(create=True)

    def choose(text):
        prefs.allowed_folders = text

    yield choose
    prefs.allowed_folders = ""


@pytest.fixture
def obj_scene(tmp_path):
    """A scene whose OBJ names a material library in a folder beside the scene's."""
    private = tmp_path / "private"
    private.mkdir()
    (private / "lib.mtl").write_text("newmtl m\nKd 1 0 0\n")
    folder = tmp_path / "scene"
    folder.mkdir()
    obj = write_box_obj(str(folder / "box.obj"), (-1, -1, -1), (1, 1, 1))
    with open(obj) as stream:
        text = stream.read()
    with open(obj, "w") as stream:
        stream.write(f"mtllib {private / 'lib.mtl'}\nusemtl m\n" + text)
    path = write_scene(str(folder), "scene.json", {"objects": [{"mesh": "box.obj"}]})
    return path, str(private)


def _refused(path, *words, **kwargs):
    before = fingerprint()
    with pytest.raises(SceneImportError) as info:
        scene_builder.import_scene_file(path, **kwargs)
    message = str(info.value)
    assert "\n" not in message, message
    for word in ("is outside the scene's folder", "Allowed Folders", "--allow-folder") + words:
        assert word in message, (word, message)
    assert fingerprint() == before
    return message


def test_an_obj_mtllib_outside_is_refused_and_the_scene_unchanged(scene, obj_scene):
    path, private = obj_scene
    message = _refused(path, "box.obj: mtllib", "lib.mtl", os.path.dirname(path))
    assert message.startswith(path + ": objects[0].mesh: "), message


def test_the_preference_allows_other_folders(scene, obj_scene, allowed_folders_preference):
    path, private = obj_scene
    allowed_folders_preference(f"/nonexistent/folder; {private}")
    collection = scene_builder.import_scene_file(path)
    assert [o for o in collection.all_objects if o.type == 'MESH']


def test_allowed_folders_argument_as_the_cli_passes_it(scene, obj_scene):
    path, private = obj_scene
    collection = scene_builder.import_scene_file(path, allowed_folders=[private])
    assert [o for o in collection.all_objects if o.type == 'MESH']
    scene = cli.open_scene(path, allowed_folders=[private])
    assert any(o.type == 'MESH' for o in scene.objects)
    with pytest.raises(cli.CLIError, match="outside the scene's folder"):
        cli.open_scene(path)


def test_cli_flag_allows_the_folder(tmp_path, obj_scene):
    path, private = obj_scene
    refused = run_cli([path, str(tmp_path / "a.png"), "--resolution", "16x16"], cwd=tmp_path)
    assert refused.returncode != 0
    assert "mtllib" in refused.stderr and "--allow-folder" in refused.stderr, refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    allowed = run_cli([path, str(tmp_path / "b.png"), "--resolution", "16x16",
                       "--allow-folder", "/nonexistent", "--allow-folder", private],
                      cwd=tmp_path)
    assert allowed.returncode == 0, allowed.stderr
    assert (tmp_path / "b.png").stat().st_size > 0


def test_a_gltf_image_uri_outside_is_refused(scene, tmp_path):
    (tmp_path / "secret.png").write_bytes(b"not an image")
    gltf = write_box_gltf(str(tmp_path / "scene/box.gltf"))
    with open(gltf) as stream:
        document = json.load(stream)
    document["images"] = [{"uri": "../secret.png"}]
    with open(gltf, "w") as stream:
        json.dump(document, stream)
    path = write_scene(str(tmp_path / "scene"), "scene.json", {"objects": [{"mesh": "box.gltf"}]})
    _refused(path, "images[0].uri ../secret.png")
    collection = scene_builder.import_scene_file(path, allowed_folders=[str(tmp_path)])
    assert [o for o in collection.all_objects if o.type == 'MESH']


@pytest.mark.parametrize("mesh", ["ABSOLUTE", "../outside/box.obj", "link/box.obj"])
def test_a_mesh_path_outside_the_scene_folder_is_refused(scene, tmp_path, mesh):
    outside = tmp_path / "outside"
    outside.mkdir()
    obj = write_box_obj(str(outside / "box.obj"), (-1, -1, -1), (1, 1, 1))
    folder = tmp_path / "scene"
    folder.mkdir()
    os.symlink(outside, folder / "link")
    mesh = obj if mesh == "ABSOLUTE" else mesh
    path = write_scene(str(folder), "scene.json", {"objects": [{"mesh": mesh}]})
    _refused(path, "objects[0].mesh: mesh file", "box.obj")
    collection = scene_builder.import_scene_file(path, allowed_folders=[str(outside)])
    assert [o for o in collection.all_objects if o.type == 'MESH']


def test_files_in_subfolders_and_the_bundled_scenes_import(scene, tmp_path):
    models = tmp_path / "scene" / "models"
    models.mkdir(parents=True)
    (tmp_path / "scene" / "tex").mkdir()
    (tmp_path / "scene" / "tex" / "wood.png").write_bytes(b"not an image")
    obj = write_box_obj(str(models / "box.obj"), (-1, -1, -1), (1, 1, 1))
    with open(obj) as stream:
        text = stream.read()
    with open(obj, "w") as stream:
        stream.write("mtllib box.mtl\nusemtl m\n" + text)
    (models / "box.mtl").write_text("newmtl m\nmap_Kd ../tex/wood.png\n")
    path = write_scene(str(tmp_path / "scene"), "scene.json",
                       {"objects": [{"mesh": "models/box.obj"}]})
    scene_builder.import_scene_file(path)
    # The bundled scenes name meshes in the add-on's data folder beside their own.
    scene_builder.import_scene_file(paths.default_scene_path())


def test_a_scenes_folder_reads_its_siblings_but_not_further_up(scene, tmp_path):
    (tmp_path / "project/data/gltf").mkdir(parents=True)
    write_box_obj(str(tmp_path / "project/data/gltf/box.obj"), (-1, -1, -1), (1, 1, 1))
    write_box_obj(str(tmp_path / "project/box.obj"), (-1, -1, -1), (1, 1, 1))
    folder = str(tmp_path / "project/data/scenes")
    sibling = write_scene(folder, "a.json", {"objects": [{"mesh": "../gltf/box.obj"}]})
    scene_builder.import_scene_file(sibling)
    above = write_scene(folder, "b.json", {"objects": [{"mesh": "../../box.obj"}]})
    _refused(above, "objects[0].mesh: mesh file")
