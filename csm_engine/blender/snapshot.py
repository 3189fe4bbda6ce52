"""Per-frame snapshot: everything the pipeline needs, read out of Blender once per frame.

Owns the translation from Blender's conventions to the engine's plain data: camera matrices
(from the scene camera for final renders, from the region for the viewport), lights (sun,
point, spot) in EEVEE's units (docs/lighting.md), the World colour used as ambient, the CSM
settings (a ``settings_model.Settings``), and the list of mesh instances with their world
matrices. After ``take()`` returns, nothing downstream reads ``bpy`` properties (the
evaluated objects in ``mesh_sources`` are only handed to the mesh cache for extraction).
"""

import itertools

import numpy as np

from . import compat
from ..core import settings_model, world_light
from ..core.camera import CameraView
from ..core.frame import FrameSnapshot, MeshInstance, PointLight, SpotLight, Sun
from ..core.frame_layout import MAX_POINT_LIGHTS, MAX_SPOT_LIGHTS
from ..core.matrices import inverse_rigid
from ..core.settings_model import SETTINGS, Settings

# Light units are EEVEE's (docs/lighting.md), so a scene keeps its exposure when it switches
# engine. Sun Strength is irradiance (W/m^2) and the diffuse BRDF is albedo/pi (Lambert), as
# in eevee_light.cc shape_radiance_get ("Convert irradiance to radiance") and the legacy
# eevee_lights.c light_shape_power_get.
#
# A PHYSICAL point or spot light of Power P watts is a sphere whose radiance is
# P / (4 pi r^2 * pi) (eevee_light.cc shape_radiance_get, LA_LOCAL/LA_SPOT; legacy
# "1/(4*r²*Pi²)"); seen from distance d >> r it gives the irradiance P / (4 pi d^2), i.e. a
# point of radiant intensity P / (4 pi) W/sr (point_radiance_get: "Convert radiant flux to
# intensity"). Spot lights use the same conversion: the cone only masks the light.
WATTS_TO_INTENSITY = 1.0 / (4.0 * np.pi)
# A course light (LINEAR_RADIUS) of colour c and 100 W shines as in the course's programs:
# c * (1 - d/radius) * albedo * cos. With the albedo/pi BRDF that is the irradiance
# pi * c * (1 - d/radius): 100 W is the file's intensity of one.
COURSE_WATTS_PER_UNIT = 100.0
# EEVEE's default Light Threshold (Render > Lights): where no Custom Distance is set, a
# physical light ends where its irradiance falls below it (attenuation_radius_get).
DEFAULT_LIGHT_THRESHOLD = 0.01
# Radius of a course light whose file radius is missing (linear falloff to zero there).
DEFAULT_LIGHT_RADIUS = 20.0


def _matrix(m):
    return np.array(m, dtype=np.float64).reshape(4, 4)


def camera_from_scene(scene, depsgraph, width, height):
    """The scene camera as the final render sees it (lens, sensor, shift, ortho, clipping)."""
    camera = scene.camera
    if camera is None:
        return None
    camera_eval = camera.evaluated_get(depsgraph)
    render = scene.render
    clip_from_view = _matrix(camera_eval.calc_matrix_camera(
        depsgraph, x=width, y=height,
        scale_x=render.pixel_aspect_x, scale_y=render.pixel_aspect_y))
    world_from_view = _matrix(camera_eval.matrix_world.normalized())
    data = camera_eval.data
    # The camera's own clip values are exact; the matrix holds them only to float32.
    clip_start = getattr(data, "clip_start", None)
    clip_end = getattr(data, "clip_end", None)
    return CameraView(world_from_view, clip_from_view, width, height, clip_start, clip_end)


def camera_from_region(region_data, width, height):
    """The 3D viewport's view, whether looking through a camera or free."""
    clip_from_view = _matrix(region_data.window_matrix)
    view_from_world = _matrix(region_data.view_matrix)
    return CameraView(inverse_rigid(view_from_world), clip_from_view, width, height)


def _significant(value):
    """A float32 property's value without its binary noise (20.000000298 -> 20.0)."""
    return float(f"{value:.7g}")


def settings_snapshot(scene, warnings=None):
    """The CSM settings as a ``Settings`` value. A value outside its setting's range
    (possible from Python or a hand-edited file, which bypass the UI's limits) is clamped
    to the model's hard limits and named in ``warnings``, so a frame never runs with 99
    cascades or a 1-texel map; an enum value that is no item falls back to the default."""
    csm = scene.csm
    values = {}
    for setting in SETTINGS:
        name = setting.identifier
        value = getattr(csm, name)
        if setting.kind == settings_model.ENUM:
            valid = setting.identifiers
            if value not in valid:
                if warnings is not None:
                    warnings.append(f"setting {name} = {value!r} is not one of "
                                    f"{', '.join(valid)}; using {setting.default!r}")
                value = setting.default
        elif setting.is_number:
            hard_min, hard_max = setting.hard_range
            is_vector = setting.kind == settings_model.FLOAT_VECTOR
            items = list(value) if is_vector else [value]
            cast = int if setting.kind == settings_model.INT else _significant
            fixed = []
            for item in items:
                clamped = min(max(item, hard_min), hard_max) \
                    if item == item else hard_min
                if clamped != item and warnings is not None:
                    warnings.append(f"setting {name} = {_significant(item):g} is outside "
                                    f"{hard_min:g}..{hard_max:g}; using "
                                    f"{_significant(clamped):g}")
                fixed.append(cast(clamped))
            value = tuple(fixed) if is_vector else fixed[0]
        else:
            value = bool(value)
        values[name] = value
    return Settings(**values)


def _world_light(world, warnings=None):
    """The World's radiance as one colour (``_world_color``) and, when an Environment
    Texture feeds the Background, as spherical harmonics (``environment_sh``, times the
    Background strength; else None)."""
    color = _world_color(world, warnings)
    tree = None if world is None else compat.shading_nodes(world)
    if tree is None:
        return color, None
    for node in tree.nodes:
        if node.type == 'BACKGROUND' and node.inputs[0].is_linked:
            source = node.inputs[0].links[0].from_node
            image = getattr(source, "image", None)
            if source.type == 'TEX_ENVIRONMENT' and image is not None and \
                    getattr(source, "projection", 'EQUIRECTANGULAR') == 'EQUIRECTANGULAR':
                sh = environment_sh(image)
                if sh is not None:
                    return color, sh * node.inputs[1].default_value
            break
    return color, None


def _world_color(world, warnings=None):
    """The World's radiance as one colour: the Background colour times its strength; when
    an Environment (or Image) Texture feeds the colour, the texture's average over the
    sphere (see ``environment_average``); for anything else linked (a Sky Texture, a node
    setup), the World's viewport colour, and a warning saying so."""
    if world is None:
        return np.zeros(3)
    tree = compat.shading_nodes(world)
    if tree is not None:
        for node in tree.nodes:
            if node.type == 'BACKGROUND':
                color = node.inputs[0]
                strength = node.inputs[1].default_value
                if not color.is_linked:
                    return np.array(color.default_value[:3]) * strength
                source = color.links[0].from_node
                image = getattr(source, "image", None)
                if source.type in {'TEX_ENVIRONMENT', 'TEX_IMAGE'} and image is not None:
                    average = environment_average(image, source.type == 'TEX_ENVIRONMENT')
                    if average is not None:
                        return average * strength
                if warnings is not None:
                    warnings.append(f"World '{world.name}': its colour comes from a "
                                    f"{source.bl_label} node, which CSM cannot evaluate; "
                                    "ambient and background use the World's viewport colour")
                break
    return np.array(world.color[:3], dtype=np.float64)


# Image -> (what the average was taken from, the average): an environment map is read once.
_ENVIRONMENT_AVERAGES = {}


def _srgb_to_linear(c):
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _environment_pixels(image):
    """An environment image's linear rgb (height, width, 3), row 0 at the bottom; None when
    it has no pixels."""
    try:
        width, height = image.size
        channels = image.channels
    except (ReferenceError, AttributeError):
        return None
    if width * height == 0 or channels < 3:
        return None
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(height, width, channels)[..., :3].astype(np.float64)
    # Byte images hold their colour space's values; float images (HDR, EXR) are linear.
    if not image.is_float and image.colorspace_settings.name in {"sRGB", "sRGB EOTF"}:
        rgb = _srgb_to_linear(rgb)
    return rgb


# Image -> (what the coefficients were taken from, the coefficients).
_ENVIRONMENT_SH = {}


def environment_sh(image):
    """The radiance of an equirectangular environment image as spherical harmonics
    (``core.world_light.radiance_sh``, (9, 3)); None when it has no pixels. Read once per
    image until it changes."""
    try:
        key = (image.name, tuple(image.size), image.filepath_raw, bool(image.is_dirty))
    except (ReferenceError, AttributeError):
        return None
    held = _ENVIRONMENT_SH.get(image.name)
    if held is not None and held[0] == key:
        return held[1]
    rgb = _environment_pixels(image)
    coefficients = None if rgb is None else world_light.radiance_sh(rgb)
    _ENVIRONMENT_SH[image.name] = (key, coefficients)
    return coefficients


def environment_average(image, equirectangular=True):
    """Mean linear radiance (rgb) of an environment image over the sphere: rows of an
    equirectangular map are weighted by the solid angle they cover (cos of latitude).
    None when the image has no pixels (a missing file)."""
    held = _ENVIRONMENT_AVERAGES.get(getattr(image, "name", None))
    try:
        key = (image.name, *image.size, image.filepath_raw, bool(image.is_dirty))
    except (ReferenceError, AttributeError):
        return None
    if held is not None and held[0] == key:
        return held[1]
    rgb = _environment_pixels(image)
    if rgb is None:
        return None
    height = rgb.shape[0]
    if equirectangular:
        latitude = (np.arange(height) + 0.5) / height * np.pi - 0.5 * np.pi
        weights = np.cos(latitude)
    else:
        weights = np.ones(height)
    average = (rgb.mean(axis=1) * weights[:, None]).sum(axis=0) / weights.sum()
    _ENVIRONMENT_AVERAGES[image.name] = (key, average)
    return average


def light_falloff(light, setting):
    """The falloff a point or spot light gets: the Light Falloff setting, or per light
    (``PER_LIGHT``): course lights, which the scene importer marks with the custom
    property ``csm_radius``, fall off linearly to it; every other light is physical."""
    if setting != 'PER_LIGHT':
        return setting
    return 'LINEAR_RADIUS' if "csm_radius" in light else 'PHYSICAL'


def _light_radius(light, falloff, light_threshold):
    """Where the light ends (scene units). LINEAR_RADIUS: the course radius (the Custom
    Distance, which the importer sets to it, else ``csm_radius``). PHYSICAL: EEVEE's
    influence radius (eevee_light.cc attenuation_radius_get): the Custom Distance if set,
    else the distance at which max(colour) * power / 100 W reaches the Light Threshold by
    the inverse-square law."""
    if getattr(light, "use_custom_distance", False):
        return float(light.cutoff_distance)
    if falloff == 'LINEAR_RADIUS':
        return float(light["csm_radius"]) if "csm_radius" in light else DEFAULT_LIGHT_RADIUS
    power = max(light.color[:3]) * abs(light.energy) / 100.0
    return float(np.sqrt(max(power, 0.0) / max(light_threshold, 1e-16)))


def _light_threshold(scene):
    eevee = getattr(scene, "eevee", None)
    threshold = getattr(eevee, "light_threshold", None) if eevee is not None else None
    return float(threshold) if threshold is not None else DEFAULT_LIGHT_THRESHOLD


def _local_light_color(light, falloff):
    """Colour x power in the units of the falloff (see the constants above)."""
    color = np.array(light.color[:3], dtype=np.float64) * light.energy
    if falloff == 'LINEAR_RADIUS':
        return color * (np.pi / COURSE_WATTS_PER_UNIT)
    return color * WATTS_TO_INTENSITY


# Object types whose evaluated geometry is a mesh CSM draws.
_MESH_TYPES = frozenset({'MESH', 'CURVE', 'SURFACE', 'FONT', 'META'})


def _no_faces(original):
    """Whether an object's own (unevaluated) mesh has no faces. Asked before the evaluated
    mesh: even reading an evaluated object's ``data`` makes Blender finish evaluating it (a
    live Subdivision modifier runs then), which a final render whose meshes are unchanged
    never needs (``mesh_cache.recipe``)."""
    mesh = getattr(original, "data", None) if original is not None else None
    return mesh is None or not len(getattr(mesh, "polygons", ()))


def take(depsgraph, camera, is_viewport=False):
    """Read one frame's worth of plain data out of the evaluated depsgraph."""
    scene = depsgraph.scene_eval if hasattr(depsgraph, "scene_eval") else depsgraph.scene
    warnings = []
    snap = FrameSnapshot(camera=camera, settings=settings_snapshot(scene, warnings),
                         warnings=warnings,
                         film_transparent=bool(scene.render.film_transparent),
                         pixel_filter_width=float(getattr(scene.render, "filter_size", 1.5)),
                         is_viewport=bool(is_viewport), frame=int(scene.frame_current),
                         scene_name=scene.name)
    # A uniform World of radiance L: a diffuse surface receives the irradiance pi * L and
    # sends back albedo/pi of it, so ambient light is L * albedo, as in EEVEE. An
    # environment image lights each normal by its own irradiance (spherical harmonics).
    world_color, world_sh = _world_light(scene.world, warnings)
    light_threshold = _light_threshold(scene)
    snap.ambient = world_color * snap.settings.ambient_strength
    if world_sh is not None:
        snap.world_sh = world_sh * snap.settings.ambient_strength
    snap.background = world_color

    matrices = []
    suns = []
    instances = snap.instances
    mesh_sources = snap.mesh_sources
    check_shown = None      # whether instances have show_self (asked once, not per object)
    # Per object: its MeshInstance fields besides the matrix. Copies of one object
    # (instances) share them, so 100,000 copies ask Blender once, not 100,000 times.
    per_object = {}
    rows = []               # per mesh instance: its per_object fields, in order
    for instance in depsgraph.object_instances:
        if is_viewport:
            if check_shown is None:
                check_shown = hasattr(instance, "show_self")
            if check_shown and not instance.show_self:
                continue
        obj = instance.object
        kind = obj.type
        if kind == 'LIGHT':
            if obj.data.type == 'SUN':
                # The matrix copied: the iterator reuses the instance.
                suns.append((obj, _matrix(instance.matrix_world)))
            else:
                _add_light(snap, obj, _matrix(instance.matrix_world), light_threshold)
        elif kind in _MESH_TYPES:
            original = obj.original
            if kind == 'MESH' and not instance.is_instance and _no_faces(original) and \
                    obj.data is not None and not len(obj.data.polygons):
                # Nothing to draw, and no bounds to add: e.g. an object whose Geometry
                # Nodes make only instances (the copies of a mesh file), which come next.
                continue
            key = original.name if original else obj.name
            fields = per_object.get(key)
            if fields is None:
                # Blender 3.0+ per-object ray visibility, as EEVEE and Cycles honour it:
                # hidden from the camera but still casting, or seen but casting no shadow.
                # (key, visible_camera, casts_shadow, terminator_offset, name, asset)
                fields = per_object[key] = (
                    key, bool(getattr(obj, "visible_camera", True)),
                    bool(getattr(obj, "visible_shadow", True)),
                    compat.terminator_geometry_offset(obj), key,
                    _asset_name(original or obj))
            rows.append(fields)
            # A copy: the instance (and a Matrix that wraps it) is reused by the iterator.
            matrices.append(instance.matrix_world.copy())
            if key not in mesh_sources:
                # An instance's object (a collection instance's copy) is a temporary the
                # iterator reuses: the mesh is read later, from the evaluated original.
                mesh_sources[key] = original.evaluated_get(depsgraph) \
                    if instance.is_instance and original else obj
    if suns:
        obj, world_from_light = suns[0] if len(suns) == 1 else _active_sun(depsgraph, suns)
        _add_light(snap, obj, world_from_light, light_threshold)
    # One conversion for every instance (one Matrix at a time costs twice as much).
    world_from_objects = np.fromiter(
        itertools.chain.from_iterable(itertools.chain.from_iterable(matrices)),
        dtype=np.float64, count=16 * len(matrices)).reshape(-1, 4, 4)
    instances.extend(MeshInstance(key, matrix, visible_camera, casts_shadow, offset, name,
                                  asset)
                     for (key, visible_camera, casts_shadow, offset, name, asset), matrix
                     in zip(rows, world_from_objects))
    # Shadow-casting point lights first: the plan gives the first ones cube maps, and the
    # lighting pass loops over them apart from the rest (a stable sort keeps their order).
    snap.points.sort(key=lambda light: not light.casts_shadow)
    for kind, lights, limit in (("point", snap.points, MAX_POINT_LIGHTS),
                                ("spot", snap.spots, MAX_SPOT_LIGHTS)):
        if len(lights) > limit:
            warnings.append(f"{len(lights)} {kind} lights: CSM draws {limit}, "
                            f"{len(lights) - limit} are left out")
    return snap


def _asset_name(obj):
    """The name Cryptomatte Asset gives an object: its topmost parent's, as Blender's."""
    while obj.parent is not None:
        obj = obj.parent
    return obj.name


def _active_sun(depsgraph, suns):
    """Of several suns, the one that casts CSM's cascades: the scene's active sun, the one
    the sidebar's Light panel edits (``light_controls.sun_object``), else the first."""
    from .light_controls import sun_object
    active = sun_object(depsgraph.scene, depsgraph.view_layer)
    for obj, world_from_light in suns:
        if active is not None and obj.original == active:
            return obj, world_from_light
    return suns[0]


def _add_light(snap, obj, world_from_light, light_threshold=DEFAULT_LIGHT_THRESHOLD):
    light = obj.data
    color = np.array(light.color[:3], dtype=np.float64)
    axis_z = world_from_light[:3, 2] / max(np.linalg.norm(world_from_light[:3, 2]), 1e-12)
    position = world_from_light[:3, 3].copy()
    casts_shadow = bool(getattr(light, "use_shadow", True))
    if light.type == 'SUN':
        if snap.sun is None:   # the first sun casts the cascades; CSM has one sun
            # Strength is the irradiance (W/m^2) on a surface facing the sun.
            snap.sun = Sun(to_light=axis_z, color=color * light.energy,
                           casts_shadow=casts_shadow, name=obj.name,
                           angle=float(getattr(light, "angle", 0.0)))
        return
    if light.type not in {'POINT', 'SPOT'}:
        return      # AREA lights are not supported by CSM (neither by the course)
    falloff = light_falloff(light, snap.settings.light_falloff)
    radius = _light_radius(light, falloff, light_threshold)
    if light.type == 'POINT':
        snap.points.append(PointLight(
            position, _local_light_color(light, falloff), radius, falloff,
            casts_shadow=casts_shadow,
            clip_start=float(getattr(light, "shadow_buffer_clip_start", 0.05) or 0.05),
            source_radius=float(getattr(light, "shadow_soft_size", 0.0))))
    else:
        rotation = world_from_light.copy()
        for c in range(3):
            rotation[:3, c] /= max(np.linalg.norm(rotation[:3, c]), 1e-12)
        snap.spots.append(SpotLight(
            position=position, direction=-axis_z,
            color=_local_light_color(light, falloff),
            radius=radius, spot_size=float(light.spot_size),
            spot_blend=float(light.spot_blend), casts_shadow=casts_shadow,
            world_from_light=rotation,
            clip_start=float(getattr(light, "shadow_buffer_clip_start", 0.05) or 0.05),
            falloff=falloff,
            source_radius=float(getattr(light, "shadow_soft_size", 0.0))))

