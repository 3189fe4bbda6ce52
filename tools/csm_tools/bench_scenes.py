"""Scenes the benchmark builds in Blender: the Suzanne field, and the ground plane and
world every benchmark scene shares (the real-model scenes in ``bench_models`` too).

Owns how a benchmark scene is staged, so the synthetic and the real-model scenes light
and frame their subjects the same way. Every builder starts from ``cli.open_scene()``
(factory reset, add-on registered, Standard view transform). bpy is imported inside the
functions.
"""

import math

GROUND_GREY = (0.6, 0.6, 0.6)
WORLD_COLOR = (0.05, 0.06, 0.08)
SUZANNE_TRIANGLES = 968           # per subdivision level, times 4 ** level


def set_base_colour(material, rgb):
    """Set a material's colour both where CSM reads it (the Principled BSDF's Base Color
    when the material uses nodes, else ``diffuse_color``) and in the viewport colour."""
    material.diffuse_color = (*rgb, 1.0)
    if getattr(material, "node_tree", None) is not None:
        for node in material.node_tree.nodes:
            if node.type == 'BSDF_PRINCIPLED':
                node.inputs["Base Color"].default_value = (*rgb, 1.0)


def add_ground(size, z=0.0):
    """A grey square plane of side ``size`` metres centred under the origin."""
    import bpy
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, z))
    ground = bpy.context.object
    ground.name = "ground"
    material = bpy.data.materials.new("ground")
    set_base_colour(material, GROUND_GREY)
    ground.data.materials.append(material)
    return ground


def add_camera(scene, location, target, lens=35.0):
    """A camera at ``location`` looking at ``target`` (world points), up +Z, clip end 500;
    made the scene's camera."""
    import bpy
    from mathutils import Vector
    bpy.ops.object.camera_add(location=location)
    camera = bpy.context.object
    camera.rotation_euler = (Vector(target) - Vector(location)).to_track_quat(
        '-Z', 'Y').to_euler()
    camera.data.lens = lens
    camera.data.clip_end = 500.0
    scene.camera = camera
    return camera


def add_world(scene):
    """The dim blue-grey world every benchmark scene has (ambient light for CSM)."""
    import bpy
    world = bpy.data.worlds.new("bench_world")
    world.color = WORLD_COLOR
    scene.world = world
    return world


def subdivided_monkey(level, live=False):
    """One Suzanne mesh with ``level`` subdivisions (968 * 4**level triangles): applied,
    or with ``live`` a Subdivision modifier left on the object (Blender evaluates it for
    every render, as in a user's scene)."""
    import bpy
    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.object
    modifier = obj.modifiers.new("subdivide", 'SUBSURF')
    modifier.levels = level
    modifier.render_levels = level
    if not live:
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    if hasattr(obj.data, "shade_smooth"):      # 4.1+; older meshes keep flat normals
        obj.data.shade_smooth()
    return obj


def build_field_scene(monkeys, level=2, share_mesh=False, live=False, distinct=False):
    """Suzannes on a square grid over a ground plane, a sun and a camera seeing them all.

    Deterministic: positions and rotations come from the grid index only. With
    ``share_mesh`` every monkey links one mesh (scaling sweeps); otherwise each has its own
    copy, like separately modelled objects, so editing one uploads one. With ``live`` the
    Subdivision modifier stays on every object (not applied). With ``distinct`` each copy
    has one vertex moved by a millimetre per index, so no two meshes are the same (a
    final render cannot read one for all).
    """
    import bpy
    from csm_engine.blender import cli
    scene = cli.open_scene()
    template = subdivided_monkey(level, live)
    side = max(int(math.ceil(math.sqrt(monkeys))), 1)
    spacing = 3.0
    extent = side * spacing
    objects = [template]
    for index in range(1, monkeys):
        data = template.data if share_mesh else template.data.copy()
        if distinct and not share_mesh:
            data.vertices[0].co.z += 0.001 * index
        obj = bpy.data.objects.new(f"Suzanne.{index:04d}", data)
        if live:
            modifier = obj.modifiers.new("subdivide", 'SUBSURF')
            modifier.levels = modifier.render_levels = level
        scene.collection.objects.link(obj)
        objects.append(obj)
    for index, obj in enumerate(objects):
        row, column = divmod(index, side)
        obj.location = ((column - (side - 1) / 2) * spacing, (row - (side - 1) / 2) * spacing,
                        1.0)
        obj.rotation_euler = (0.0, 0.0, math.radians((index * 37) % 360))
    add_ground(extent + 2 * spacing)

    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(40), math.radians(20),
                                                   math.radians(30)))
    bpy.context.object.data.energy = 3.0
    distance = 0.75 * extent + 8.0
    bpy.ops.object.camera_add(location=(0.0, -distance, 0.6 * distance),
                              rotation=(math.radians(58), 0.0, 0.0))
    camera = bpy.context.object
    camera.data.clip_end = 4.0 * distance
    scene.camera = camera
    add_world(scene)
    return scene


def animate_one_object(scene, frames):
    """Key the first Suzanne rising 2 m over ``frames`` frames (frame_start=1); the rest
    of the scene stays still."""
    obj = next(o for o in scene.objects if o.name.startswith("Suzanne"))
    scene.frame_start, scene.frame_end = 1, frames
    obj.keyframe_insert("location", frame=1)
    obj.location.z += 2.0
    obj.keyframe_insert("location", frame=frames)
    scene.frame_set(1)
    return obj


def scene_triangles(scene):
    """Triangles of every mesh object in ``scene``, after modifiers."""
    import bpy
    depsgraph = bpy.context.evaluated_depsgraph_get()
    count = 0
    for obj in scene.objects:
        if obj.type == 'MESH':
            mesh = obj.evaluated_get(depsgraph).data
            mesh.calc_loop_triangles()
            count += len(mesh.loop_triangles)
    return count
