"""Many references to one mesh file: one mesh in Blender, drawn at every reference.

Owns how a mesh file that several scene objects reference is built. The file is imported
once, into a source collection ``<stem> (source)`` below the import's collection and
excluded from the view layers (so only its copies show); one copies object
``<stem> (N copies)`` holds one vertex per scene object, in the file's order: the vertex's
position is the object's location, its attributes ``csm_rotation`` (Euler XYZ, radians)
and ``csm_scale`` its rotation and scale, and its Geometry Nodes modifier (the node group
``CSM Copies``) puts an instance of the source collection on every vertex.

NOTE: 100,000 references as objects of their own (linked duplicates under a parent empty
each) took about two minutes and 11 GB to import; as empties instancing the collection,
11 s and 2.4 GB; as vertices of one object, under a second and a few hundred MB. Blender's
depsgraph hands the copies to renderers as instances of the source objects, so CSM (and
EEVEE, Cycles) draws every copy of a mesh from one upload.

The matrices follow ``core/conventions.object_matrix_zup``; the file's Euler order
(Z, then Y, then X in the file's Y-up axes) is turned into the XYZ Euler angles that
Instance on Points takes.
"""

import bpy
import numpy as np

from ..core import conventions
from . import compat
from .import_transaction import layer_collection_for

NODE_GROUP_NAME = "CSM Copies"
ROTATION_ATTRIBUTE = "csm_rotation"     # Euler XYZ, radians, per vertex (copy)
SCALE_ATTRIBUTE = "csm_scale"           # per vertex (copy), Blender's axes


def _rotations_yup(degrees):
    """(N, 3) file Euler degrees -> (N, 3, 3) ``Rx * Ry * Rz`` (``conventions.rotation_xyz``)."""
    x, y, z = np.radians(np.asarray(degrees, dtype=np.float64)).T
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    one, zero = np.ones_like(x), np.zeros_like(x)
    rx = np.stack([one, zero, zero, zero, cx, -sx, zero, sx, cx], axis=-1).reshape(-1, 3, 3)
    ry = np.stack([cy, zero, sy, zero, one, zero, -sy, zero, cy], axis=-1).reshape(-1, 3, 3)
    rz = np.stack([cz, -sz, zero, sz, cz, zero, zero, zero, one], axis=-1).reshape(-1, 3, 3)
    return rx @ ry @ rz


def euler_xyz(rotations):
    """(N, 3, 3) rotation matrices -> (N, 3) Blender XYZ Euler angles (radians), the
    matrix being ``Rz * Ry * Rx``; at gimbal lock (cos y = 0) the Z angle is 0."""
    r = np.asarray(rotations, dtype=np.float64)
    cos_y = np.hypot(r[:, 0, 0], r[:, 1, 0])
    regular = cos_y > 1e-9
    x = np.where(regular, np.arctan2(r[:, 2, 1], r[:, 2, 2]),
                 np.arctan2(-r[:, 1, 2], r[:, 1, 1]))
    y = np.arctan2(-r[:, 2, 0], cos_y)
    z = np.where(regular, np.arctan2(r[:, 1, 0], r[:, 0, 0]), 0.0)
    return np.stack([x, y, z], axis=-1)


def _placements(scene_objects):
    """(N, 3) translations, file Euler degrees and scales of the scene objects."""
    arrays = [np.array([getattr(o, name).as_tuple() for o in scene_objects],
                       dtype=np.float64).reshape(-1, 3)
              for name in ("translate", "rotate", "scale")]
    return arrays


def placement_matrices(scene_objects):
    """Each scene object's world matrix in Blender's axes, (N, 4, 4):
    ``conventions.object_matrix_zup`` for all of them at once."""
    translate, rotate, scale = _placements(scene_objects)
    yup = np.zeros((len(translate), 4, 4))
    yup[:, :3, :3] = _rotations_yup(rotate) * scale[:, None, :]
    yup[:, :3, 3] = translate
    yup[:, 3, 3] = 1.0
    return conventions.ZUP_FROM_YUP @ yup @ conventions.YUP_FROM_ZUP


def copy_transforms(scene_objects):
    """Each scene object's placement as Blender location, XYZ Euler (radians) and scale:
    (N, 3) arrays each, equal to ``conventions.object_matrix_zup``."""
    translate, rotate, scale = _placements(scene_objects)
    zup_from_yup = conventions.ZUP_FROM_YUP[:3, :3]
    location = translate @ zup_from_yup.T
    rotation = zup_from_yup @ _rotations_yup(rotate) @ zup_from_yup.T
    # A scale along the file's (x, y, z) is one along Blender's (x, z, y).
    return location, euler_xyz(rotation), scale[:, [0, 2, 1]]


def _vector_output(node):
    """The Named Attribute node's vector output (3.x lists one output per data type)."""
    return next(socket for socket in node.outputs if socket.type == 'VECTOR')


def _node_group(source):
    """Instance on Points of ``source`` (a collection), rotated and scaled per vertex by
    the ``csm_rotation`` and ``csm_scale`` attributes."""
    tree = bpy.data.node_groups.new(NODE_GROUP_NAME, 'GeometryNodeTree')
    compat.new_node_group_socket(tree, "Geometry", 'INPUT', 'NodeSocketGeometry')
    compat.new_node_group_socket(tree, "Geometry", 'OUTPUT', 'NodeSocketGeometry')
    nodes, links = tree.nodes, tree.links
    group_in = nodes.new("NodeGroupInput")
    group_out = nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeCollectionInfo")
    info.transform_space = 'ORIGINAL'
    info.inputs["Collection"].default_value = source
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    rotation = nodes.new("GeometryNodeInputNamedAttribute")
    rotation.data_type = 'FLOAT_VECTOR'
    rotation.inputs["Name"].default_value = ROTATION_ATTRIBUTE
    scale = nodes.new("GeometryNodeInputNamedAttribute")
    scale.data_type = 'FLOAT_VECTOR'
    scale.inputs["Name"].default_value = SCALE_ATTRIBUTE
    links.new(group_in.outputs[0], on_points.inputs["Points"])
    links.new(info.outputs[0], on_points.inputs["Instance"])
    links.new(_vector_output(rotation), on_points.inputs["Rotation"])
    links.new(_vector_output(scale), on_points.inputs["Scale"])
    links.new(on_points.outputs[0], group_out.inputs[0])
    for x, node in enumerate((group_in, info, rotation, scale, on_points, group_out)):
        node.location = (200.0 * x, 0.0)
    return tree


def add_copies(planned, source, collection, name):
    """The copies object of ``planned`` (the scene objects referencing one file, in the
    file's order) instancing the collection ``source``, linked to ``collection``."""
    location, rotation, scale = copy_transforms([item.scene_object for item in planned])
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(planned))
    mesh.vertices.foreach_set("co", location.astype(np.float32).ravel())
    for attribute_name, values in ((ROTATION_ATTRIBUTE, rotation), (SCALE_ATTRIBUTE, scale)):
        attribute = mesh.attributes.new(attribute_name, 'FLOAT_VECTOR', 'POINT')
        attribute.data.foreach_set("vector", values.astype(np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj["csm_mesh"] = planned[0].mesh_path
    obj["csm_scene_objects"] = [item.index for item in planned]
    modifier = obj.modifiers.new(NODE_GROUP_NAME, 'NODES')
    modifier.node_group = _node_group(source)
    collection.objects.link(obj)
    return obj


def exclude_from_view_layers(scene, source):
    """Keep the source collection out of every view layer of ``scene``: its objects show
    only as copies (Blender still evaluates them for the copies)."""
    for view_layer in scene.view_layers:
        layer_collection = layer_collection_for(view_layer, source)
        if layer_collection is not None:
            layer_collection.exclude = True
