"""Scene builders and reference renders shared by the in-process bpy tests.

Each builder is one plain Blender call or two (``bpy.ops`` as a user would click), so a test
that uses them still shows its whole set-up. Also here: the CPU ray cast the shadow tests
take as the truth (a ``mathutils`` BVH of the scene's triangles), the course's shadow test
scene as a fixture, and a render by Blender's own engines (EEVEE, Cycles) read back as
linear floats, for tests that compare CSM with them. Only ``bpy``, ``mathutils`` and numpy:
tests of the engine never import the measuring tools (``csm_tools``).

Imported by name (``from tests.bpy.scenes import ...``); the fixture ``pillar_field`` is
imported into the test modules that use it.
"""
import os

import bpy
import numpy as np
import pytest
from mathutils import Vector
from mathutils.bvhtree import BVHTree

from csm_engine.blender.compat import enable_shading_nodes, shading_nodes

COURSE_SUN = Vector((0.3, 0.7, -0.6))   # the course's (0.3, -0.6, -0.7), Y-up -> Z-up


# ---- objects ---------------------------------------------------------------------------------

def add_box(location, scale, size=2.0):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    obj = bpy.context.object
    obj.scale = scale
    return obj


def add_ground(size, location=(0, 0, 0)):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    return bpy.context.object


def add_sun(direction):
    """A sun whose light travels along ``direction``."""
    bpy.ops.object.light_add(type='SUN')
    sun = bpy.context.object
    sun.rotation_euler = (-Vector(direction)).to_track_quat('Z', 'Y').to_euler()
    return sun


def add_light(kind, location, energy, target=(0, 0, 0), **settings):
    """A light of ``kind`` ('POINT', 'SPOT', 'SUN', 'AREA') at ``location`` aimed at
    ``target``; ``settings`` are set on its light data."""
    bpy.ops.object.light_add(type=kind, location=location)
    obj = bpy.context.object
    obj.data.energy = energy
    obj.rotation_euler = (Vector(target) - Vector(location)).to_track_quat('-Z', 'Y').to_euler()
    for name, value in settings.items():
        setattr(obj.data, name, value)
    return obj


def add_camera(scene, location, target, lens=35.0, clip_end=300.0):
    bpy.ops.object.camera_add(location=location)
    camera = bpy.context.object
    camera.rotation_euler = (Vector(target) - Vector(location)).to_track_quat('-Z', 'Y').to_euler()
    camera.data.lens = lens
    camera.data.clip_end = clip_end
    scene.camera = camera
    return camera


def set_world_color(scene, rgb):
    """The World colour as a user sets it (Surface > Color), with or without nodes."""
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.color = rgb
    tree = shading_nodes(world)
    if tree is not None:
        for node in tree.nodes:
            if node.type == 'BACKGROUND':
                node.inputs[0].default_value = (*rgb, 1.0)
                node.inputs[1].default_value = 1.0


def principled(name, base=(0.8, 0.8, 0.8), roughness=0.5):
    """A new material whose Principled BSDF has this base colour and roughness."""
    material = bpy.data.materials.new(name)
    enable_shading_nodes(material)
    bsdf = next(n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    return material


@pytest.fixture
def pillar_field(empty_scene):
    """The course's shadow test: a ground plane and 39 boxes scaled (1,3,1) (Y-up), 5 apart."""
    scene = empty_scene
    add_ground(240, location=(95, 0, 0))
    for i in range(39):
        add_box((i * 5.0, 0, 3.0), (1, 1, 3))
    sun = add_sun(COURSE_SUN)
    add_camera(scene, (-20, 50, 32), (35, 0, 0), lens=30)
    return scene, sun


# ---- the CPU ray cast --------------------------------------------------------------------------

def world_bvh(scene):
    """One BVH of every mesh triangle in world space."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    verts, polys = [], []
    for obj in scene.objects:
        if obj.type != 'MESH':
            continue
        mesh = obj.evaluated_get(depsgraph).to_mesh()
        mesh.calc_loop_triangles()
        base = len(verts)
        matrix = obj.matrix_world
        verts += [matrix @ v.co for v in mesh.vertices]
        polys += [[base + i for i in tri.vertices] for tri in mesh.loop_triangles]
        obj.evaluated_get(depsgraph).to_mesh_clear()
    return BVHTree.FromPolygons(verts, polys)


def sun_facing_points(images, to_light, step=2):
    """(pixel rows, cols), world points and normals of covered pixels facing the sun."""
    position = images["position"][::step, ::step]
    normal = images["normal"][::step, ::step, :3]
    covered = position[..., 3] > 0.5
    facing = (normal @ np.asarray(to_light, dtype=np.float32)) > 0.1
    rows, cols = np.nonzero(covered & facing)
    return rows * step, cols * step, position[rows, cols, :3], normal[rows, cols]


def ray_cast_shadowed(bvh, points, normals, to_light):
    to_light = Vector(to_light).normalized()
    shadowed = np.zeros(len(points), dtype=bool)
    for i, (p, n) in enumerate(zip(points, normals)):
        origin = Vector(p) + Vector(n) * 1e-3 + to_light * 1e-3
        shadowed[i] = bvh.ray_cast(origin, to_light)[0] is not None
    return shadowed


# ---- Blender's own engines -------------------------------------------------------------------

def eevee_engine_id():
    """4.2 .. 4.x call EEVEE Next 'BLENDER_EEVEE_NEXT'; 3.4 and 5.0 call it 'BLENDER_EEVEE'."""
    items = {item.identifier for item in
             bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"


def blender_render(scene, engine_id, path):
    """Render ``scene`` with one of Blender's engines (``engine_id``; the scene's engine is
    CSM again afterwards) and return the render result as linear float RGBA (H, W, 4), rows
    bottom first as Blender keeps them. Python cannot read the Render Result's pixels, so
    they go through a 32-bit OpenEXR file at ``path``, which keeps scene-linear values (no
    view transform)."""
    scene.render.engine = engine_id
    try:
        bpy.ops.render.render()
    finally:
        scene.render.engine = "CSM"
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):      # 5.0: image, multilayer image or video
        settings.media_type = 'IMAGE'
    settings.file_format = 'OPEN_EXR'
    settings.color_depth = '32'
    settings.color_mode = 'RGBA'
    bpy.data.images["Render Result"].save_render(filepath=str(path), scene=scene)
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(height, width, 4)


def render_eevee(scene, folder):
    """EEVEE's linear combined pass, rows bottom-up (see ``blender_render``)."""
    return blender_render(scene, eevee_engine_id(),
                          os.path.join(str(folder), f"eevee_{scene.name}.exr"))
