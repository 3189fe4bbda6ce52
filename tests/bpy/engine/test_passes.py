"""The render passes as a compositing user sees them: the light passes add up to Combined,
Depth and Normal are EEVEE's, Mist follows the World's settings, and Blender's own
Cryptomatte node isolates each object as it does from Cycles' Cryptomatte.

Blender's engines' passes are read through the compositor (Python cannot read a Render
Result's pixels): the pass under test goes to the compositor's output, which is saved as a
32-bit OpenEXR (``tests.bpy.scenes.blender_render``)."""
import os

import bpy
import numpy as np
import pytest

from tests.bpy.scenes import (add_box, add_camera, add_ground, add_sun, blender_render,
                              eevee_engine_id, principled, set_world_color)

WIDTH, HEIGHT = 96, 72
LIGHT_PASSES = ("use_pass_diffuse_direct", "use_pass_diffuse_color", "use_pass_glossy_direct",
                "use_pass_glossy_color", "use_pass_emit", "use_pass_environment")


def _scene(scene):
    """A ground, a metal box, a glossy sphere and an emissive cone under a sun and a grey
    World, seen from above at an angle."""
    ground = add_ground(12)
    ground.data.materials.append(principled("Ground", (0.6, 0.5, 0.4), roughness=0.8))
    box = add_box((-1.5, 0.5, 1.0), (1, 1, 1))
    metal = principled("Metal", (0.9, 0.6, 0.3), roughness=0.3)
    metal.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    box.data.materials.append(metal)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(1.5, 0.5, 1.0))
    sphere = bpy.context.object
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(principled("Gloss", (0.2, 0.4, 0.8), roughness=0.2))
    bpy.ops.mesh.primitive_cone_add(location=(0.0, -2.0, 1.0))
    cone = bpy.context.object
    glow = principled("Glow", (0.3, 0.3, 0.3))
    inputs = glow.node_tree.nodes["Principled BSDF"].inputs
    inputs["Emission Color" if "Emission Color" in inputs else "Emission"].default_value = \
        (1.0, 0.5, 0.2, 1.0)
    if "Emission Strength" in inputs:
        inputs["Emission Strength"].default_value = 2.0
    cone.data.materials.append(glow)
    add_sun((0.4, 0.3, -1.0)).data.energy = 3.0
    set_world_color(scene, (0.1, 0.12, 0.15))
    add_camera(scene, (0, -9, 7), (0, 0, 0.5), lens=35)
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.csm.fxaa = False
    scene.csm.render_samples = 1
    for name, obj in (("Ground", ground), ("Box", box), ("Sphere", sphere), ("Cone", cone)):
        obj.name = name
    return (ground, box, sphere, cone)


def _csm(scene):
    from csm_engine.blender import engine
    scene.render.engine = "CSM"
    result = engine.render_final(scene, keep_images=True)
    assert result.error is None, result.error
    return result


def _eroded(mask, steps=1):
    for _ in range(steps):
        inner = mask.copy()
        inner[1:, :] &= mask[:-1, :]
        inner[:-1, :] &= mask[1:, :]
        inner[:, 1:] &= mask[:, :-1]
        inner[:, :-1] &= mask[:, 1:]
        mask = inner
    return mask


def _composite_output(scene):
    """The compositor's output (a node tree the test fills) and its Render Layers node,
    for this host: 5.0's compositing node group, or 4.x's scene node tree."""
    if hasattr(scene, "compositing_node_group"):            # 5.0
        tree = bpy.data.node_groups.new("Passes under test", "CompositorNodeTree")
        scene.compositing_node_group = tree
        tree.interface.new_socket("Image", in_out='OUTPUT', socket_type='NodeSocketColor')
        output = tree.nodes.new("NodeGroupOutput").inputs[0]
    else:
        scene.use_nodes = True
        tree = scene.node_tree
        tree.nodes.clear()
        output = tree.nodes.new("CompositorNodeComposite").inputs["Image"]
    scene.render.use_compositing = True
    return tree, tree.nodes.new("CompositorNodeRLayers"), output


def _render_through(scene, engine_id, folder, wire):
    """``engine_id``'s render with the compositor's output fed by ``wire(tree,
    render_layers)`` (an output socket); linear RGBA (H, W, 4), rows bottom first."""
    tree, layers, output = _composite_output(scene)
    tree.links.new(wire(tree, layers), output)
    try:
        return blender_render(scene, engine_id, os.path.join(str(folder),
                                                             f"{engine_id}.exr"))
    finally:
        if hasattr(scene, "compositing_node_group"):
            scene.compositing_node_group = None
            bpy.data.node_groups.remove(tree)
        else:
            scene.use_nodes = False


def _recombined_error(images):
    rebuilt = (images["Diffuse Direct"] * images["Diffuse Color"] +
               images["Glossy Direct"] * images["Glossy Color"] +
               images["Emission"] + images["Environment"])
    return np.abs(rebuilt - images["combined"][..., :3]).max(axis=-1)


def test_light_passes_recombine_to_combined(empty_scene):
    scene = empty_scene
    _scene(scene)
    layer = scene.view_layers[0]
    for name in LIGHT_PASSES:
        setattr(layer, name, True)
    images = _csm(scene).images
    error = _recombined_error(images)
    covered = images["aux"][..., 3] > 0.5
    print(f"recombined - Combined: max {error.max():.2e} over {error.size} pixels")
    assert error.max() <= 1e-3, f"{int((error > 1e-3).sum())} pixels off by up to {error.max()}"
    # Each pass carries its share: the metal box's light is all specular, the cone emits,
    # the World shows where nothing is.
    assert images["Diffuse Color"][covered].max() > 0.3
    assert images["Glossy Color"][covered].max() > 0.5      # the metal's base colour
    assert images["Emission"].max() > 1.0
    assert images["Environment"][~covered].min() > 0.09


def test_light_passes_are_averaged_over_render_samples(empty_scene):
    """With 4 render samples the passes are averaged as Combined is: where every sample saw
    the same object (Cryptomatte coverage 1, away from its edges) or the World, they still
    add up to Combined (products of averages differ only where a colour varies)."""
    scene = empty_scene
    _scene(scene)
    layer = scene.view_layers[0]
    for name in LIGHT_PASSES:
        setattr(layer, name, True)
    layer.use_pass_cryptomatte_object = True
    scene.csm.render_samples = 4
    images = _csm(scene).images
    error = _recombined_error(images)
    coverage = images["CryptoObject00"][..., 1]
    unmixed = _eroded((coverage >= 0.999) | (coverage == 0.0))
    print(f"4 samples: {unmixed.mean():.1%} of pixels unmixed, recombined - Combined there: "
          f"max {error[unmixed].max():.2e}")
    # (Passes taken from one sample instead: 5 % of these pixels off by more than 1e-3.)
    assert unmixed.mean() > 0.8
    assert error[unmixed].max() <= 1e-3, \
        f"{int((error[unmixed] > 1e-3).sum())} unmixed pixels off by up to {error.max()}"


def test_passes_off_write_nothing_extra(empty_scene):
    """A render without passes reads back only Combined and the aux target."""
    scene = empty_scene
    _scene(scene)
    images = _csm(scene).images
    assert not {"Diffuse Direct", "Mist", "CryptoObject00"} & set(images)


@pytest.mark.parametrize("pass_name,setting", [("Depth", "use_pass_z"),
                                               ("Normal", "use_pass_normal"),
                                               ("Mist", "use_pass_mist"),
                                               ("Position", "use_pass_position")])
def test_geometry_passes_match_eevee(empty_scene, tmp_path, pass_name, setting):
    scene = empty_scene
    _scene(scene)
    setattr(scene.view_layers[0], setting, True)
    mist = scene.world.mist_settings
    mist.start, mist.depth, mist.falloff = 6.0, 8.0, 'QUADRATIC'     # across the scene
    scene.eevee.taa_render_samples = 1
    scene.render.filter_size = 0.01
    csm = _csm(scene)
    ours = csm.images[pass_name]
    covered = _eroded(csm.images["aux"][..., 3] > 0.5, 2)
    from csm_engine.blender.compat import render_pass_name
    eevee = _render_through(scene, eevee_engine_id(), tmp_path,
                            lambda tree, layers: layers.outputs[render_pass_name(pass_name)])
    theirs = eevee[..., :ours.shape[-1]]
    if pass_name in ("Depth", "Position"):
        # Relative to the distance from the camera.
        distance = np.linalg.norm(csm.images["Position"] - np.array(
            scene.camera.matrix_world.translation), axis=-1) if pass_name == "Position" \
            else theirs[..., 0]
        error = np.abs(ours - theirs).max(axis=-1)[covered] / distance[covered]
        # EEVEE's Position agrees to about half-float steps (measured: mean 1.2e-4).
        tolerance = 1e-4 if pass_name == "Depth" else 1e-3
    else:
        # Normals: CSM's come from the G-buffer's octahedral 2 x 16-bit ones (within
        # ~6e-5), but Blender's own draws (EEVEE's) take vertex normals packed into 10-bit
        # integers: measured max 1.6e-3, mean 1.1e-4 on the smooth sphere. Mist is 0..1.
        error = np.abs(ours - theirs)[covered].max(axis=-1)
        tolerance = 2e-3 if pass_name == "Normal" else 1e-3
    print(f"{pass_name}: CSM - EEVEE over {int(covered.sum())} pixels: max {error.max():.2e}, "
          f"mean {error.mean():.2e}")
    assert np.percentile(error, 99) <= tolerance and error.mean() <= tolerance / 4, \
        f"{pass_name} differs from EEVEE's by up to {error.max():.2e}"


def test_mist_follows_the_world(empty_scene):
    scene = empty_scene
    _scene(scene)
    scene.view_layers[0].use_pass_mist = True
    scene.view_layers[0].use_pass_position = True
    mist = scene.world.mist_settings
    results = {}
    for falloff in ("LINEAR", "QUADRATIC"):
        mist.start, mist.depth, mist.falloff = 6.0, 8.0, falloff
        results[falloff] = _csm(scene).images
    images = results["LINEAR"]
    covered = images["aux"][..., 3] > 0.5
    # Distance from the camera to the surface seen (the Position pass).
    camera_position = np.array(scene.camera.matrix_world.translation)
    positions = images["Position"]
    distance = np.linalg.norm(positions - camera_position, axis=-1)
    expected = np.clip((distance - 6.0) / 8.0, 0.0, 1.0)
    assert np.abs(images["Mist"][..., 0] - expected)[covered].max() < 1e-4
    assert np.all(images["Mist"][~covered] == 1.0)
    inside = (expected > 0.0) & (expected < 1.0)
    assert inside[covered].mean() > 0.5          # the mist's range runs across the scene
    quadratic = results["QUADRATIC"]["Mist"][..., 0]
    assert np.abs(quadratic - expected ** 2)[covered].max() < 1e-4


def _matte(scene, engine_id, folder, layer_name, object_name):
    def wire(tree, layers):
        node = tree.nodes.new("CompositorNodeCryptomatteV2")
        node.source = 'RENDER'
        node.scene = scene
        node.layer_name = layer_name
        node.matte_id = object_name
        return node.outputs["Matte"]
    return _render_through(scene, engine_id, folder, wire)[..., 0]


def test_cryptomatte_isolates_objects_as_cycles_does(empty_scene, tmp_path):
    scene = empty_scene
    objects = _scene(scene)
    layer = scene.view_layers[0]
    layer.use_pass_cryptomatte_object = True
    layer.use_pass_cryptomatte_material = True
    scene.csm.render_samples = 16          # coverage from anti-aliasing samples
    scene.cycles.samples = 64
    scene.cycles.use_denoising = False
    layer_name = f"{layer.name}.CryptoObject"
    for name in (obj.name for obj in objects):
        csm = _matte(scene, "CSM", tmp_path, layer_name, name)
        cycles = _matte(scene, "CYCLES", tmp_path, layer_name, name)
        # The object's pixels in either; a pixel agrees when its coverage does within a
        # quarter (both are anti-aliased: Cycles' 64 samples have noise of about 1/16).
        shown = (csm > 0.0) | (cycles > 0.0)
        agree = (np.abs(csm - cycles) <= 0.25)[shown].mean()
        print(f"Cryptomatte {name}: {int(shown.sum())} pixels, {agree:.2%} agree with Cycles "
              f"(largest difference {np.abs(csm - cycles).max():.3f})")
        assert shown.sum() > 50, f"{name} is not in view"
        assert agree >= 0.99, f"{name}: only {agree:.2%} of its pixels agree with Cycles"
    # The material layer isolates the metal box's material alone.
    csm = _matte(scene, "CSM", tmp_path, f"{layer.name}.CryptoMaterial", "Metal")
    box = _matte(scene, "CSM", tmp_path, layer_name, "Box")
    assert ((csm > 0.5) == (box > 0.5)).mean() > 0.999


@pytest.mark.parametrize("kind,shift", [("PERSP", (0.0, 0.0)), ("PERSP", (0.2, -0.1)),
                                        ("ORTHO", (0.1, 0.3))])
def test_position_pass_points_are_the_unprojected_pixels(kind, shift):
    """The Position and Mist passes' fast unprojection gives the general 4x4 one's points."""
    from csm_engine.core.camera import CameraProjection, CameraView, world_positions
    from csm_engine.render.passes import world_points
    projection = CameraProjection(kind=kind, shift_x=shift[0], shift_y=shift[1],
                                  aspect=40 / 30)
    world_from_view = np.eye(4)
    world_from_view[:3, :3] = [[0.0, -0.6, 0.8], [1.0, 0.0, 0.0], [0.0, 0.8, 0.6]]
    world_from_view[:3, 3] = (3.0, -2.0, 5.0)
    camera = CameraView(world_from_view, projection.clip_from_view(), 40, 30)
    depth = np.random.default_rng(1).uniform(0.5, 50.0, (30, 40))
    expected = world_positions(camera, depth)
    assert np.abs(world_points(camera, depth) - expected).max() < 1e-9 * 50


def test_cryptomatte_metadata_reaches_the_openexr_header(empty_scene, tmp_path):
    """Readers outside Blender find the layer's name, hash, conversion and manifest."""
    scene = empty_scene
    _scene(scene)
    scene.view_layers[0].use_pass_cryptomatte_object = True
    scene.render.engine = "CSM"
    bpy.ops.render.render()
    path = str(tmp_path / "crypto.exr")
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):
        settings.media_type = 'MULTI_LAYER_IMAGE'
    settings.file_format = 'OPEN_EXR_MULTILAYER'
    bpy.data.images["Render Result"].save_render(filepath=path, scene=scene)
    with open(path, "rb") as handle:
        header = handle.read(16384)
    from csm_engine.core import cryptomatte
    layer = f"{scene.view_layers[0].name}.CryptoObject"
    key = f"cryptomatte/{cryptomatte.murmurhash3_32(layer):08x}"[:19].encode()
    assert key + b"/name" in header and key + b"/manifest" in header
    assert b"MurmurHash3_32" in header and b"uint32_to_float32" in header
    for name in ("Ground", "Box", "Sphere", "Cone"):
        entry = f'"{name}":"{cryptomatte.murmurhash3_32(name):08x}"'.encode()
        assert entry in header, f"{name} missing from the manifest"
    assert b"CryptoObject00" in header


def test_geometry_passes_are_the_pixel_centres_with_render_samples(empty_scene):
    """Depth, Normal and Position of a 4-sample render are the unjittered sample's: the
    one-sample render's values, never a blend of two surfaces at an edge."""
    scene = empty_scene
    _scene(scene)
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = layer.use_pass_position = True
    one = _csm(scene).images
    scene.csm.render_samples = 4
    four = _csm(scene).images
    for name in ("Depth", "Normal", "Position"):
        assert np.array_equal(one[name], four[name]), name
