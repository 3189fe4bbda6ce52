"""Full materials as a user sees them: normal maps, emission, metallic and specular,
metallic-roughness textures (Blender's glTF wiring and the course's convention), hashed
alpha in the image and in shadows, backface culling, mip-mapped textures at grazing angles.

Scenes are built with plain Blender calls; every texture is made here in numpy. Each test
checks pixels, and says which number would be wrong if the feature were missing.
"""
import math
import os

import bpy
import numpy as np
import pytest

from csm_engine.blender.compat import enable_shading_nodes
from tests.bpy.bpy_helpers import render_result, render_scene
from tests.bpy.scenes import (add_box, add_camera, add_ground, add_sun, render_eevee,
                              set_world_color)

SAVE = os.environ.get("CSM_TEST_IMAGES")     # a folder: PNGs of the renders, to look at


def _save(name, rgb):
    if not SAVE:
        return
    image = bpy.data.images.new(name, rgb.shape[1], rgb.shape[0], alpha=True)
    pixels = np.ones((rgb.shape[0], rgb.shape[1], 4), dtype=np.float32)
    pixels[..., :3] = np.clip(rgb[::-1, :, :3], 0.0, 1.0) ** (1 / 2.2)
    image.pixels.foreach_set(pixels.ravel())
    image.filepath_raw = os.path.join(SAVE, name + ".png")
    image.file_format = 'PNG'
    image.save()
    bpy.data.images.remove(image)


def principled_material(name, base=(0.8, 0.8, 0.8), roughness=0.5, **inputs):
    material = bpy.data.materials.new(name)
    enable_shading_nodes(material)
    bsdf = next(n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    for key, value in inputs.items():
        socket = next(bsdf.inputs.get(n) for n in key.split("|") if bsdf.inputs.get(n))
        socket.default_value = value
    return material, bsdf


def numpy_image(name, rgba, non_color=False):
    """An image from an (H, W, 4) array (rows top first), packed into the file."""
    height, width = rgba.shape[:2]
    image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=False)
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], dtype=np.float32).ravel())
    image.pack()
    if non_color:
        image.colorspace_settings.name = 'Non-Color'
    return image


def image_node(material, image):
    node = material.node_tree.nodes.new('ShaderNodeTexImage')
    node.image = image
    return node


def add_plane(size, location=(0, 0, 0), material=None):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    plane = bpy.context.object
    if material is not None:
        plane.data.materials.append(material)
    return plane


def top_camera(scene, height=10.0, ortho_scale=4.0, below=False):
    z = -height if below else height
    camera = add_camera(scene, (0, 0, z), (0, 0, 0))
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = ortho_scale
    return camera


def lit_scene(scene, sun_direction=(0, 0, -1), strength=math.pi, world=(0.0, 0.0, 0.0)):
    set_world_color(scene, world)
    sun = add_sun(sun_direction)
    sun.data.energy = strength
    return sun


def set_alpha_blend(material, transparent_shadow=True):
    """Alpha Blend as a user picks it on each version (Settings > Blend Mode / Render
    Method), with transparent shadows."""
    if hasattr(material, "surface_render_method"):          # 4.2+
        material.surface_render_method = 'BLENDED'
        material.use_transparent_shadow = transparent_shadow
    else:
        material.blend_method = 'BLEND'
        material.shadow_method = 'HASHED' if transparent_shadow else 'OPAQUE'


# ---- normal maps -------------------------------------------------------------------------

def normal_mapped_material(name, tilt_degrees, strength=1.0):
    """A flat tangent-space normal map leaning ``tilt_degrees`` towards the tangent (+U)."""
    material, bsdf = principled_material(name, roughness=1.0)
    tilt = math.radians(tilt_degrees)
    rgba = np.empty((8, 8, 4), dtype=np.float32)
    rgba[...] = (0.5 + 0.5 * math.sin(tilt), 0.5, 0.5 + 0.5 * math.cos(tilt), 1.0)
    node = image_node(material, numpy_image(name, rgba, non_color=True))
    normal_map = material.node_tree.nodes.new('ShaderNodeNormalMap')
    normal_map.inputs["Strength"].default_value = strength
    links = material.node_tree.links
    links.new(node.outputs["Color"], normal_map.inputs["Color"])
    links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    return material


@pytest.mark.parametrize("ngon", [False, True], ids=["quads (MikkTSpace)", "n-gon (numpy)"])
def test_normal_map_turns_the_lit_side_brighter_and_the_other_darker(empty_scene, ngon):
    """Three flat surfaces under a sun low in +X: the map leaning to +U (= +X here) faces the
    sun more and is brighter than the plain one; the map leaning to -U is darker. Without
    normal maps all three would be equal; with tangents the wrong way round, swapped."""
    scene = empty_scene
    lit_scene(scene, sun_direction=(-1.0, 0.0, -1.0))
    brightness = {}
    for index, tilt in enumerate((-40, 0, 40)):
        x = (index - 1) * 2.5
        if ngon:
            bpy.ops.mesh.primitive_circle_add(vertices=12, radius=1.0, fill_type='NGON',
                                              location=(x, 0, 0))
            obj = bpy.context.object
            # One 12-gon (Blender refuses its tangents) with UVs = x, y, so +U is +X.
            mesh = obj.data
            layer = mesh.uv_layers.new(name="UVMap")
            corners = np.empty(len(mesh.loops), dtype=np.int32)
            mesh.loops.foreach_get("vertex_index", corners)
            coords = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
            mesh.vertices.foreach_get("co", coords)
            layer.data.foreach_set("uv", coords.reshape(-1, 3)[corners, :2].ravel() * 0.5)
            obj.data.materials.append(normal_mapped_material(f"tilt{tilt}", tilt))
        else:
            add_plane(2.0, (x, 0, 0), normal_mapped_material(f"tilt{tilt}", tilt))
    top_camera(scene, ortho_scale=8.0)
    images = render_scene(scene, 160, 80)
    _save(f"normal_map_{'ngon' if ngon else 'quads'}", images["combined"])
    color = images["combined"][..., :3].mean(axis=-1)
    for index, tilt in enumerate((-40, 0, 40)):
        col = 80 + (index - 1) * 50
        brightness[tilt] = float(color[35:45, col - 5:col + 5].mean())
    normal_x = {tilt: float(images["normal"][40, 80 + (i - 1) * 50, 0])
                for i, tilt in enumerate((-40, 0, 40))}
    # Lambert: cos(45 - 40) / cos(45) = 1.41 brighter, cos(85) / cos(45) = 0.12.
    assert brightness[40] > 1.25 * brightness[0] > 0.0, brightness
    assert brightness[-40] < 0.3 * brightness[0], brightness
    assert normal_x[40] == pytest.approx(math.sin(math.radians(40)), abs=0.05), normal_x
    assert normal_x[-40] == pytest.approx(-math.sin(math.radians(40)), abs=0.05), normal_x


def test_normal_map_strength_zero_is_the_plain_surface(empty_scene):
    scene = empty_scene
    lit_scene(scene, sun_direction=(-1.0, 0.0, -1.0))
    add_plane(2.0, (-1.25, 0, 0), normal_mapped_material("full", 40, strength=1.0))
    add_plane(2.0, (1.25, 0, 0), normal_mapped_material("none", 40, strength=0.0))
    top_camera(scene, ortho_scale=6.0)
    normal = render_scene(scene, 120, 60)["normal"]
    assert normal[30, 30, 0] > 0.5
    assert abs(normal[30, 90, 0]) < 0.02 and normal[30, 90, 2] > 0.99


def test_fallback_tangents_agree_with_mikktspace_on_a_grid():
    """The numpy tangents (used where Blender refuses: n-gons) point where MikkTSpace's do."""
    from csm_engine.blender import compat, mesh_cache
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
    mesh = bpy.context.object.data
    positions, normals, uvs, triangles, _slots, _bounds = mesh_cache.extract_arrays(mesh)
    mikk = compat.corner_tangents(mesh)
    assert mikk is not None
    # No Blender tangents: force the numpy path.
    fallback = mesh_cache.corner_tangents(type("NoTangents", (), {
        "loops": (), "uv_layers": ()})(), "", positions, normals, uvs, triangles)
    agree = np.sum(mikk[:, :3] * fallback[:, :3], axis=1)
    valid = np.linalg.norm(mikk[:, :3], axis=1) > 0.5
    assert np.median(agree[valid]) > 0.98
    assert np.mean(np.sign(mikk[valid, 3]) == fallback[valid, 3]) > 0.95


def test_only_normal_mapped_meshes_pay_for_tangents(empty_scene):
    from csm_engine.render import gpu_mesh
    scene = empty_scene
    lit_scene(scene)
    add_plane(2.0, (-1.5, 0, 0), normal_mapped_material("bumpy", 20))
    add_plane(2.0, (1.5, 0, 0))
    top_camera(scene, ortho_scale=6.0)
    from csm_engine.blender import engine
    engine.forget_final_render_meshes()
    uploaded = render_result(scene, 32, 16).upload_bytes
    corners, triangles = 4, 2
    plain = corners * gpu_mesh.BYTES_PER_CORNER + triangles * gpu_mesh.BYTES_PER_TRIANGLE
    assert uploaded == 2 * plain + corners * gpu_mesh.BYTES_PER_TANGENT, uploaded


# ---- emission ----------------------------------------------------------------------------

def test_emission_shows_without_lights_and_in_full_shadow(empty_scene):
    """Emission Color x Strength adds as is (EEVEE's units): with no lamp and a black World
    the pixel is exactly the emission; in a box's full shadow under a sun it is still
    there; a plain Emission shader does the same."""
    scene = empty_scene
    set_world_color(scene, (0.0, 0.0, 0.0))
    glowing, _ = principled_material(
        "glow", base=(0.5, 0.5, 0.5), **{"Emission Color|Emission": (1.0, 0.5, 0.25, 1.0),
                                          "Emission Strength": 2.0})
    add_plane(2.0, (-1.5, 0, 0), glowing)
    emission_only = bpy.data.materials.new("emission shader")
    enable_shading_nodes(emission_only)
    tree = emission_only.node_tree
    for node in list(tree.nodes):
        if node.type != 'OUTPUT_MATERIAL':
            tree.nodes.remove(node)
    shader = tree.nodes.new('ShaderNodeEmission')
    shader.inputs["Color"].default_value = (0.2, 0.4, 1.0, 1.0)
    shader.inputs["Strength"].default_value = 3.0
    tree.links.new(shader.outputs["Emission"], tree.nodes["Material Output"].inputs["Surface"])
    add_plane(2.0, (1.5, 0, 0), emission_only)
    top_camera(scene, ortho_scale=6.0)
    color = render_scene(scene, 120, 60)["combined"]
    assert np.allclose(color[30, 30, :3], (2.0, 1.0, 0.5), atol=2e-3), color[30, 30]
    assert np.allclose(color[30, 90, :3], (0.6, 1.2, 3.0), atol=2e-3), color[30, 90]

    # A sun and a roof over the glowing plane: full shadow, emission unchanged.
    add_sun((0.0, 0.0, -1.0)).data.energy = 5.0
    add_box((-1.5, 0, 3.0), (1.5, 1.5, 0.1))                 # a roof
    bpy.context.scene.camera.location.z = 2.5      # under the roof, above the plane
    shadowed = render_scene(scene, 120, 60)
    assert shadowed["aux"][30, 30, 0] < 0.01, "the plane is in the roof's shadow"
    assert np.allclose(shadowed["combined"][30, 30, :3], (2.0, 1.0, 0.5), atol=2e-3)


def test_emission_switched_off_leaves_no_glow_behind(empty_scene):
    """Frames without emission or metal draw no emission target (the pipeline keeps its
    texture at zero): after the glowing material's strength goes to 0, the next render of
    the same size shows the plain, unlit black plane, not the last frame's glow."""
    scene = empty_scene
    set_world_color(scene, (0.0, 0.0, 0.0))
    glowing, _ = principled_material(
        "glow", base=(0.5, 0.5, 0.5), **{"Emission Color|Emission": (1.0, 0.5, 0.25, 1.0),
                                          "Emission Strength": 2.0})
    add_plane(2.0, (0, 0, 0), glowing)
    top_camera(scene, ortho_scale=6.0)
    assert render_scene(scene, 120, 60)["combined"][30, 60, 0] > 1.9
    glowing.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 0.0
    dark = render_scene(scene, 120, 60)["combined"]
    assert np.abs(dark[30, 60, :3]).max() < 1e-3, dark[30, 60]
    glowing.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 2.0
    assert render_scene(scene, 120, 60)["combined"][30, 60, 0] > 1.9


# ---- metallic and specular ---------------------------------------------------------------

def _metal_and_plastic(scene, sun_direction):
    lit_scene(scene, sun_direction=sun_direction)
    metal, _ = principled_material("metal", base=(0.9, 0.3, 0.1), roughness=0.3,
                                   Metallic=1.0)
    plastic, _ = principled_material("plastic", base=(0.9, 0.3, 0.1), roughness=0.3)
    add_plane(2.0, (-1.25, 0, 0), metal)
    add_plane(2.0, (1.25, 0, 0), plastic)
    top_camera(scene, ortho_scale=6.0)
    color = render_scene(scene, 120, 60)["combined"][..., :3]
    return color[30, 30], color[30, 90]


def test_metal_has_no_diffuse(empty_scene):
    """Sun 60 degrees off the view: only the tail of the GGX highlight reaches the camera,
    so the metal is nearly black and the plastic shows its diffuse colour."""
    metal, plastic = _metal_and_plastic(empty_scene, (-math.sqrt(3.0), 0.0, -1.0))
    assert plastic[0] > 0.3, plastic
    assert metal.max() < 0.1 * plastic[0], (metal, plastic)


def test_metal_highlight_is_tinted_and_plastic_highlight_white(empty_scene):
    """Sun straight down, camera straight down: the highlight. The metal reflects its
    base colour (red >> green), the plastic adds the same white to every channel."""
    metal, plastic = _metal_and_plastic(empty_scene, (0.0, 0.0, -1.0))
    # The plastic is its albedo x cos (sun pi W/m^2) less what the specular layer above
    # reflects, plus a white highlight: k * albedo + s in every channel.
    albedo = np.array((0.9, 0.3, 0.1))
    (k, white), residual, *_ = np.linalg.lstsq(np.c_[albedo, np.ones(3)], plastic,
                                               rcond=None)
    assert 0.85 < k <= 1.0 and white > 0.05 and residual[0] < 1e-4, (k, white, plastic)
    assert metal[0] > 3.0 * metal[1] > 0.0 and metal[0] > plastic[0], (metal, plastic)
    assert metal[0] / metal[1] == pytest.approx(3.0, rel=0.05)


def test_specular_level_zero_removes_the_highlight(empty_scene):
    scene = empty_scene
    lit_scene(scene)
    dull, _ = principled_material("dull", roughness=0.2,
                                  **{"Specular IOR Level|Specular": 0.0})
    shiny, _ = principled_material("shiny", roughness=0.2,
                                   **{"Specular IOR Level|Specular": 1.0})
    add_plane(2.0, (-1.25, 0, 0), dull)
    add_plane(2.0, (1.25, 0, 0), shiny)
    top_camera(scene, ortho_scale=6.0)
    color = render_scene(scene, 120, 60)["combined"][..., :3]
    assert np.allclose(color[30, 30], 0.8, atol=5e-3), color[30, 30]
    assert color[30, 90].mean() > 0.8 + 0.2, color[30, 90]


def _surface_textured(name, rgb_left, rgb_right, course=False):
    """A material whose metallic-roughness image feeds Roughness (G) and Metallic (B)
    through Separate Color, as Blender's glTF importer wires it; left and right halves
    of the image differ."""
    material, bsdf = principled_material(name, base=(0.9, 0.3, 0.1))
    rgba = np.ones((16, 16, 4), dtype=np.float32)
    rgba[:, :8, :3] = rgb_left
    rgba[:, 8:, :3] = rgb_right
    node = image_node(material, numpy_image(name, rgba, non_color=True))
    node.interpolation = 'Closest'
    separate = material.node_tree.nodes.new('ShaderNodeSeparateColor')
    links = material.node_tree.links
    links.new(node.outputs["Color"], separate.inputs[0])
    links.new(separate.outputs["Green"], bsdf.inputs["Roughness"])
    links.new(separate.outputs["Blue"], bsdf.inputs["Metallic"])
    if course:
        material["csm_surface_convention"] = "COURSE"
    return material


def _specular_view(scene, material):
    """The G-buffer specular view: red = specular level, green = roughness, blue =
    metallic; left and right half of one plane."""
    lit_scene(scene)
    add_plane(4.0, material=material)
    top_camera(scene, ortho_scale=4.0)
    scene.csm.debug_view = 'SPECULAR'
    color = render_scene(scene, 64, 32)["combined"][..., :3]
    return color[16, 8], color[16, 56]


def test_metallic_roughness_texture_channels_are_read(empty_scene):
    material = _surface_textured("gltf", (0.0, 0.2, 1.0), (0.0, 1.0, 0.0))
    left, right = _specular_view(empty_scene, material)
    # Left: roughness 0.2, metal. Right: a fully rough dielectric, specular level 0.5.
    assert left[2] == pytest.approx(1.0, abs=0.01) and right[2] == pytest.approx(0.0, abs=0.01)
    assert left[1] == pytest.approx(0.2, abs=0.005), left
    assert right[1] == pytest.approx(1.0, abs=0.005), right
    assert right[0] == pytest.approx(0.5, abs=0.005), right


def test_course_convention_reads_specular_in_blue_and_shininess_in_green(empty_scene):
    material = _surface_textured("course", (0.0, 0.5, 0.8), (0.0, 0.0, 0.3), course=True)
    left, right = _specular_view(empty_scene, material)
    # Left: specular 0.8, shininess 256 x 0.5 = 128, the roughness whose exponent
    # 2 / r^4 - 2 that is; not metal although blue is 0.8.
    assert left[0] == pytest.approx(0.8, abs=0.01) and left[2] == 0.0, left
    assert left[1] == pytest.approx((2.0 / 130.0) ** 0.25, abs=0.005), left
    # Right: green 0 -> the course's exponent 0.01, fully rough.
    assert right[1] == pytest.approx((2.0 / 2.01) ** 0.25, abs=0.005) and \
        right[0] == pytest.approx(0.3, abs=0.01), right


# ---- hashed alpha ------------------------------------------------------------------------

def _half_transparent_plane(scene, alpha=0.5, pcf_sharpen=None):
    lit_scene(scene, world=(0.0, 0.0, 0.0))
    add_ground(40)
    glass, bsdf = principled_material("glass", base=(0.8, 0.8, 0.8))
    bsdf.inputs["Alpha"].default_value = alpha
    set_alpha_blend(glass)
    add_plane(4.0, (0, 0, 2.0), glass)
    top_camera(scene, height=20.0, ortho_scale=8.0)
    scene.csm.pcf_radius = 2
    if pcf_sharpen is not None:
        scene.csm.pcf_sharpen = pcf_sharpen
    return render_scene(scene, 128, 128)


@pytest.mark.parametrize("pcf_sharpen", [None, 1.0, 16.0], ids=["default", "sharpen 1",
                                                               "sharpen 16"])
@pytest.mark.parametrize("alpha", [0.5, 0.25])
def test_hashed_alpha_covers_and_shadows_in_proportion(empty_scene, alpha, pcf_sharpen):
    """An alpha-Blend plane of constant alpha above the ground, seen and lit from above:
    about alpha of its pixels show the plane, and the ground under it gets about 1 - alpha
    of the sun after PCF. Opaque (the old behaviour) would be 100% and a full shadow;
    a 0.5 cut-out 0% (or 100%) and no shadow (or a full one). PCF Sharpen leaves it so:
    it does not threshold what the kernel reads of a hashed caster (a 25 % glass would
    otherwise cast none)."""
    images = _half_transparent_plane(empty_scene, alpha, pcf_sharpen)
    _save(f"hashed_alpha_{alpha}", images["combined"])
    height = images["position"][40:88, 40:88, 2]
    covered = float(np.mean(height > 1.0))
    assert covered == pytest.approx(alpha, abs=0.06), covered
    visibility = images["aux"][40:88, 40:88, 0][height < 1.0]
    assert visibility.mean() == pytest.approx(1.0 - alpha, abs=0.08), visibility.mean()
    # Not a few big holes: any 8x8 block is partly covered.
    blocks = (height > 1.0).reshape(6, 8, 6, 8).mean(axis=(1, 3))
    assert blocks.min() > 0.0 and blocks.max() < 1.0


def test_sharpen_returns_where_a_hashed_caster_turns_opaque(empty_scene):
    """The partial-caster mask follows the scene: once the glass casts an opaque shadow,
    its shadow's edge is sharpened like any other (a mask left from the hashed frames
    would keep the whole footprint at the plain 3x3 ramp)."""
    scene = empty_scene
    _half_transparent_plane(scene, 0.5, pcf_sharpen=16.0)       # marks the mask
    glass = bpy.data.materials["glass"]
    set_alpha_blend(glass, transparent_shadow=False)

    def edge_pixels(sharpen):
        scene.csm.pcf_sharpen = sharpen
        images = render_scene(scene, 128, 128)
        ground = images["position"][..., 2] < 1.0
        vis = images["aux"][..., 0]
        assert vis[52:76, 52:76][ground[52:76, 52:76]].max() < 0.05   # full shadow inside
        return int(np.count_nonzero(ground & (vis > 0.02) & (vis < 0.98)))

    sharp = edge_pixels(16.0)
    plain = edge_pixels(1.0)
    assert plain > 20, plain
    # (measured: 0 of 193; a mask left marked keeps 64 unsharpened)
    assert sharp < 0.15 * plain, (sharp, plain)


def test_opaque_shadow_setting_casts_a_full_shadow(empty_scene):
    scene = empty_scene
    lit_scene(scene)
    add_ground(40)
    glass, bsdf = principled_material("glass")
    bsdf.inputs["Alpha"].default_value = 0.5
    set_alpha_blend(glass, transparent_shadow=False)
    add_plane(4.0, (0, 0, 2.0), glass)
    top_camera(scene, height=20.0, ortho_scale=8.0)
    images = render_scene(scene, 128, 128)
    height = images["position"][40:88, 40:88, 2]
    assert images["aux"][40:88, 40:88, 0][height < 1.0].max() < 0.05


# ---- backface culling --------------------------------------------------------------------

@pytest.mark.parametrize("mirrored", [False, True], ids=["plain", "negative scale"])
def test_backface_culling_hides_back_faces_only(empty_scene, mirrored):
    """A plane facing up, with Backface Culling: seen from above it is there, from below it
    is gone. A negative-scale copy still faces up (its winding is turned around, and the
    culling with it)."""
    scene = empty_scene
    lit_scene(scene, world=(0.1, 0.1, 0.1))
    material, _ = principled_material("one sided")
    material.use_backface_culling = True
    plane = add_plane(2.0, material=material)
    if mirrored:
        plane.scale = (-1.0, 1.0, 1.0)
    camera = top_camera(scene, ortho_scale=4.0)
    above = render_scene(scene, 32, 32)["aux"][16, 16, 3]
    camera.location.z = -10.0
    camera.rotation_euler = (math.pi, 0.0, 0.0)
    below = render_scene(scene, 32, 32)["aux"][16, 16, 3]
    material.use_backface_culling = False
    below_without = render_scene(scene, 32, 32)["aux"][16, 16, 3]
    assert above > 0.5, "the front face is drawn"
    assert below < 0.5, "the back face is culled"
    assert below_without > 0.5, "without culling the back face is drawn"


# ---- texture filtering -------------------------------------------------------------------

def _checker_floor(scene):
    size = 512
    cells = (np.indices((size, size)).sum(axis=0) // 2) % 2      # 2-texel squares
    rgba = np.ones((size, size, 4), dtype=np.float32)
    rgba[..., :3] = cells[..., None].astype(np.float32)
    material, bsdf = principled_material("checker", roughness=1.0)
    node = image_node(material, numpy_image("checker", rgba))
    material.node_tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    bsdf.inputs[compat_specular_name(bsdf)].default_value = 0.0
    floor = add_plane(40.0, material=material)
    set_world_color(scene, (1.0, 1.0, 1.0))
    camera = add_camera(scene, (0.0, -20.0, 1.0), (0.0, 0.0, 0.0), lens=50.0)
    return floor, camera


def compat_specular_name(bsdf):
    return "Specular IOR Level" if bsdf.inputs.get("Specular IOR Level") else "Specular"


def test_checker_at_a_grazing_angle_averages_to_grey_like_eevee(empty_scene, tmp_path):
    """A fine checker floor towards the horizon: mip-mapped, anisotropic sampling turns
    far rows into even grey (low variance along a row), as EEVEE does; one texel per
    pixel without mip-maps would alias into stripes and noise."""
    scene = empty_scene
    _checker_floor(scene)
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    scene.render.filter_size = 0.01
    eevee = scene.eevee
    eevee.taa_render_samples = 1
    for name in ("use_gtao", "use_bloom", "use_ssr", "use_raytracing", "use_shadows"):
        if hasattr(eevee, name):
            setattr(eevee, name, False)
    csm_images = render_scene(scene, 160, 120)
    csm = csm_images["combined"][..., :3].mean(axis=-1)
    covered = csm_images["aux"][..., 3] > 0.5
    eevee_image = render_eevee(scene, tmp_path)[::-1, :, :3].mean(axis=-1)
    _save("grazing_csm", csm_images["combined"])
    _save("grazing_eevee", np.repeat(eevee_image[..., None], 3, axis=-1))
    # The far rows: the topmost ten rows of floor.
    rows = np.nonzero(covered.all(axis=1))[0][:10]
    csm_far, eevee_far = csm[rows, 20:140], eevee_image[rows, 20:140]
    csm_spread, eevee_spread = float(csm_far.std()), float(eevee_far.std())
    print(f"far rows: CSM mean {csm_far.mean():.3f} std {csm_spread:.4f}; "
          f"EEVEE mean {eevee_far.mean():.3f} std {eevee_spread:.4f}")
    assert csm_spread < max(2.0 * eevee_spread, 0.03), (csm_spread, eevee_spread)
    assert csm_far.mean() == pytest.approx(eevee_far.mean(), rel=0.25)


def _course_plane_gltf(folder, green, blue):
    """A 2 x 2 plane (y = 0, facing +Y in the file) whose metallicRoughnessTexture is one
    colour (0, green, blue), as the course's files store specular and shininess."""
    import json
    texture = numpy_image("course_mr", np.tile(np.array((0.0, green, blue, 1.0),
                                                        dtype=np.float32), (4, 4, 1)))
    texture.filepath_raw = os.path.join(folder, "course_mr.png")
    texture.file_format = 'PNG'
    texture.save()
    positions = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float32)
    normals = np.tile(np.array([0, 1, 0], np.float32), (4, 1))
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    indices = np.array([0, 2, 1, 0, 3, 2], np.uint16)
    blob = positions.tobytes() + normals.tobytes() + uvs.tobytes() + indices.tobytes()
    with open(os.path.join(folder, "plane.bin"), "wb") as stream:
        stream.write(blob)
    document = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "plane", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1,
                                                   "TEXCOORD_0": 2},
                                    "indices": 3, "material": 0}]}],
        "materials": [{"name": "course", "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.8, 0.8, 1.0],
            "metallicRoughnessTexture": {"index": 0}}}],
        "textures": [{"source": 0}], "images": [{"uri": "course_mr.png"}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1, 0, -1], "max": [1, 0, 1]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 96, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 128, "byteLength": 12}],
        "buffers": [{"uri": "plane.bin", "byteLength": len(blob)}]}
    path = os.path.join(folder, "plane.gltf")
    with open(path, "w") as stream:
        json.dump(document, stream)
    scene_path = os.path.join(folder, "course.json")
    with open(scene_path, "w") as stream:
        json.dump({"camera": {"translate": {"x": 0, "y": 10, "z": 0},
                              "rotate": {"x": 90, "y": 0, "z": 0},
                              "near": 0.1, "far": 100, "FOVy": 30},
                   "objects": [{"mesh": path, "translate": {"x": 0, "y": 0, "z": 0},
                                "rotate": {"x": 0, "y": 0, "z": 0},
                                "scale": {"x": 1, "y": 1, "z": 1}}],
                   "lights": [],
                   "directional_light": {"direction": {"x": 0, "y": -1, "z": 0},
                                         "color": {"x": 1, "y": 1, "z": 1}}}, stream)
    return scene_path


def test_course_scene_import_reads_specular_in_blue_and_shininess_in_green(empty_scene,
                                                                             tmp_path):
    """A course glTF imported through a scene file: its metallicRoughnessTexture's blue is
    the specular level and green the shininess (the specular view shows them, the
    shininess as the roughness of that Blinn-Phong exponent), not
    Blender's metallic and roughness."""
    from csm_engine.blender import scene_builder
    scene = empty_scene
    scene_builder.import_scene_file(_course_plane_gltf(str(tmp_path), 0.25, 0.75), scene)
    scene.csm.debug_view = 'SPECULAR'
    color = render_scene(scene, 48, 48)["combined"][24, 24, :3]
    assert color[0] == pytest.approx(0.75, abs=0.02), f"specular from blue: {color}"
    assert color[1] == pytest.approx((2.0 / 66.0) ** 0.25, abs=0.005), \
        f"roughness of the shininess 256 x green: {color}"
    assert color[2] == 0.0, f"not metal although blue is 0.75: {color}"


def test_render_samples_blend_hashed_alpha_smoothly(empty_scene):
    """With one sample a 50% Blend plane is a dither of plane and ground pixels; with 16
    render samples each pixel averages thresholds turned by the sample index, so the image
    over the plane is nearly uniform: the mean of plane and ground."""
    scene = empty_scene
    scene.csm.fxaa = False
    one = _half_transparent_plane(scene, 0.5)["combined"][44:84, 44:84, :3].mean(axis=-1)
    scene.csm.render_samples = 16
    many = render_scene(scene, 128, 128)["combined"][44:84, 44:84, :3].mean(axis=-1)
    assert many.mean() == pytest.approx(one.mean(), rel=0.1)
    assert many.std() < 0.35 * one.std(), (many.std(), one.std())


def test_coat_adds_its_layer_and_switched_off_leaves_nothing_behind(empty_scene):
    """Two glossy red planes side by side under a sun from above; the left one has a
    Principled Coat. Seen from above, the coat's highlight brightens it; with Coat Weight
    back at 0 (the coat target is no longer written) both planes show the same pixels."""
    scene = empty_scene
    lit_scene(scene)
    coated, bsdf = principled_material("coated", base=(0.6, 0.1, 0.1), roughness=0.5)
    if "Coat Weight" not in bsdf.inputs:
        pytest.skip("Principled v1 has no Coat")
    bsdf.inputs["Coat Weight"].default_value = 1.0
    bsdf.inputs["Coat Roughness"].default_value = 0.3
    plain, _ = principled_material("plain", base=(0.6, 0.1, 0.1), roughness=0.5)
    add_plane(2.0, (-1.25, 0, 0), coated)
    add_plane(2.0, (1.25, 0, 0), plain)
    top_camera(scene, ortho_scale=6.0)
    color = render_scene(scene, 120, 60)["combined"][..., :3]
    assert color[30, 30].sum() > color[30, 90].sum() + 0.1, (color[30, 30], color[30, 90])
    bsdf.inputs["Coat Weight"].default_value = 0.0
    color = render_scene(scene, 120, 60)["combined"][..., :3]
    assert np.allclose(color[20:40, 20:40], color[20:40, 80:100], atol=1e-4)


def test_materials_and_worlds_are_read_through_the_nodes_blender_renders_with():
    """Before 5.0 Use Nodes can be off (then the material's viewport colour is what
    renders); 5.0 always renders nodes and warns that ``use_nodes`` is going away, so the
    add-on must not read it there."""
    import warnings

    from csm_engine.blender import compat, materials, snapshot
    material = bpy.data.materials.new("plain")
    material.diffuse_color = (0.8, 0.1, 0.1, 1.0)
    world = bpy.data.worlds.new("plain")
    world.color = (0.2, 0.3, 0.4)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            info = materials.material_info(material)
            sky = snapshot._world_color(world)
            material_tree = compat.shading_nodes(material)
            world_tree = compat.shading_nodes(world)
        assert not [str(w.message) for w in caught if w.category is DeprecationWarning]
        if bpy.app.version < (5, 0, 0):
            # New materials and worlds have Use Nodes off: their viewport colours render.
            assert material_tree is None and world_tree is None
            assert info.base_color == pytest.approx((0.8, 0.1, 0.1, 1.0))
            assert sky == pytest.approx((0.2, 0.3, 0.4))
        else:
            assert material_tree is material.node_tree is not None
            principled = next(n for n in material_tree.nodes if n.type == 'BSDF_PRINCIPLED')
            assert info.base_color[:3] == pytest.approx(
                tuple(principled.inputs["Base Color"].default_value)[:3])
            background = next(n for n in world_tree.nodes if n.type == 'BACKGROUND')
            assert sky == pytest.approx(tuple(background.inputs[0].default_value)[:3])
    finally:
        bpy.data.materials.remove(material)
        bpy.data.worlds.remove(world)
