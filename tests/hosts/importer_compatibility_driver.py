"""Imports mesh files one after another with the add-on's own importer calls, in one Blender.

Run by ``test_importer_compatibility.py`` in a pip bpy subprocess or in ``blender -b``.
Arguments (after ``--`` for blender): the folder holding the ``csm_engine`` package, then
the mesh files. Before each file it prints
``CSM_START <index>`` and after it ``CSM_RESULT <json>`` with the faces Blender's importer
read or its one-line error, so the parent knows which file was being read when the process
died, and restarts a fresh process at the next one.
"""

import json
import os
import sys

ARGS = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
sys.path.insert(0, ARGS[0])

import bpy  # noqa: E402

from csm_engine.blender import mesh_importers  # noqa: E402

START_PREFIX = "CSM_START "
RESULT_PREFIX = "CSM_RESULT "


def _clear():
    bpy.data.batch_remove(list(bpy.data.objects))
    for collection in (bpy.data.meshes, bpy.data.materials, bpy.data.images,
                       bpy.data.cameras, bpy.data.lights, bpy.data.actions):
        bpy.data.batch_remove(list(collection))


def _import(path):
    importer = mesh_importers._find_importer(os.path.splitext(path)[1].lower())
    if importer is None:
        return {"error": "no importer"}
    before = {obj.as_pointer() for obj in bpy.data.objects}
    try:
        result = importer.run(path)
    except Exception as err:  # importers raise anything from RuntimeError to KeyError
        return {"error": mesh_importers._importer_reason(err)[:200]}
    if 'FINISHED' not in result:
        return {"error": f"importer returned {sorted(result)}"}
    faces = sum(len(obj.data.polygons) for obj in bpy.data.objects
                if obj.as_pointer() not in before and obj.type == 'MESH')
    return {"faces": faces}


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    for index, path in enumerate(ARGS[1:]):
        print(f"{START_PREFIX}{index}", flush=True)
        outcome = _import(path)
        _clear()
        print(f"{RESULT_PREFIX}{json.dumps(outcome)}", flush=True)


main()
