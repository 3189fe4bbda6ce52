"""Blender materials as the passes draw them.

Owns reading a material's node tree into ``gpu_mesh.MaterialInfo`` (``material_info``):
the shader the active Material Output uses (Principled BSDF or Emission), its factors and
the image textures feeding them (base colour, roughness and metallic channels, emission,
a tangent-space normal map), alpha as EEVEE draws it, and shadow and backface-culling
settings. docs/materials.md lists what is read and what is not. Images are handed on as
``bpy.types.Image``; ``mesh_cache`` turns them into GPU textures.
"""

from ..render.gpu_mesh import MaterialInfo
from . import compat

# Scene import tags the materials of the course's glTF files with this custom property
# (``mesh_importers``): their metallicRoughnessTexture keeps specular in blue and
# shininess in green, which Blender's importer wires to Metallic and Roughness.
COURSE_SURFACE_TAG = ("csm_surface_convention", "COURSE")


def _find_input(node, *names):
    for name in names:
        socket = node.inputs.get(name)
        if socket is not None:
            return socket
    return None


def _upstream_image(socket, depth=0):
    """The image texture feeding a socket, through a few pass-through nodes."""
    if socket is None or not socket.is_linked or depth > 4:
        return None, None
    link = socket.links[0]
    node = link.from_node
    if node.type == 'TEX_IMAGE':
        return node.image, link.from_socket.name
    for candidate in node.inputs:
        if candidate.is_linked and candidate.type in {'RGBA', 'VALUE', 'SHADER'}:
            image, out = _upstream_image(candidate, depth + 1)
            if image is not None:
                return image, out
    return None, None


# Output socket names of Separate Color (3.3+) and Separate RGB -> texture channel.
_CHANNELS = {"Red": 0, "R": 0, "Green": 1, "G": 1, "Blue": 2, "B": 2}


def _image_channel(socket, depth=0):
    """(image, channel) feeding a scalar socket: a Separate Color/RGB output names the
    channel (Blender's glTF importer wires metallicRoughness so: G -> Roughness, B ->
    Metallic); an image's Color straight in reads red, its Alpha channel 3. Factors on the
    way (Math nodes) are passed through. (None, -1) when no image feeds it."""
    if socket is None or not socket.is_linked or depth > 4:
        return None, -1
    link = socket.links[0]
    node = link.from_node
    if node.type == 'TEX_IMAGE':
        return node.image, 3 if link.from_socket.name == "Alpha" else 0
    if node.type in compat.SEPARATE_NODE_TYPES and getattr(node, "mode", 'RGB') == 'RGB':
        image, _ = _upstream_image(node.inputs[0], depth + 1)
        return image, _CHANNELS.get(link.from_socket.name, -1)
    for candidate in node.inputs:
        if candidate.is_linked:
            image, channel = _image_channel(candidate, depth + 1)
            if image is not None:
                return image, channel
    return None, -1


def _mask_cutoff(alpha_socket):
    """The cutoff of a glTF alpha mask expressed as Math nodes (4.2+ importer, e.g.
    1 - (alpha < cutoff)), or None."""
    if alpha_socket is None or not alpha_socket.is_linked:
        return None
    node = alpha_socket.links[0].from_node
    for _ in range(3):
        if node.type != 'MATH':
            break
        for socket in node.inputs:
            if not socket.is_linked and 0.0 < socket.default_value < 1.0:
                return float(socket.default_value)
        linked = [s for s in node.inputs if s.is_linked]
        if not linked:
            break
        node = linked[0].links[0].from_node
    return None


def _surface_shader(material):
    """The node that shades a material: what the active Material Output's Surface input
    is linked to, else the tree's first Principled BSDF."""
    nodes = material.node_tree.nodes
    outputs = [n for n in nodes if n.type == 'OUTPUT_MATERIAL']
    output = next((n for n in outputs if getattr(n, "is_active_output", False)),
                  outputs[0] if outputs else None)
    surface = output.inputs.get("Surface") if output is not None else None
    if surface is not None and surface.is_linked:
        node = surface.links[0].from_node
        if node.type in {'BSDF_PRINCIPLED', 'EMISSION'}:
            return node
    return next((n for n in nodes if n.type == 'BSDF_PRINCIPLED'), None)


def _emission(info, color_socket, strength_socket):
    """Emission colour x strength (EEVEE's radiance), and an image on the colour."""
    if color_socket is None:
        return
    strength = float(strength_socket.default_value) if strength_socket is not None else 1.0
    color = tuple(color_socket.default_value)[:3]
    image, _ = _upstream_image(color_socket)
    if image is not None:
        info.emission_image = image
        color = (1.0, 1.0, 1.0)
    info.emission = tuple(c * strength for c in color)


def material_info(material):
    """What the passes draw of a material (``gpu_mesh.MaterialInfo``): the Principled BSDF's
    base colour, metallic, roughness, specular, emission and alpha (factors or image
    textures), a tangent-space Normal Map, or an Emission shader; its alpha, shadow and
    backface-culling settings. docs/materials.md lists what is read and what is not."""
    info = MaterialInfo()
    if material is None:
        return info
    info.name = material.name
    info.base_color = tuple(material.diffuse_color)
    info.backface_culling = bool(getattr(material, "use_backface_culling", False))
    info.backface_culling_shadow = compat.material_backface_culling_shadow(material)
    if compat.shading_nodes(material) is None:
        info.roughness = float(getattr(material, "roughness", 0.5))
        info.metallic = float(getattr(material, "metallic", 0.0))
        return info
    shader = _surface_shader(material)
    if shader is None:
        return info
    if shader.type == 'EMISSION':
        # Light without shading: black to every lamp, its colour x strength as emission.
        info.base_color = (0.0, 0.0, 0.0, 1.0)
        info.specular_level = 0.0
        _emission(info, _find_input(shader, "Color"), _find_input(shader, "Strength"))
        return info
    bsdf = shader
    base = _find_input(bsdf, "Base Color")
    info.base_color = tuple(base.default_value)
    image, _ = _upstream_image(base)
    if image is not None:
        info.image = image
        info.base_color = (1.0, 1.0, 1.0, 1.0)
    roughness = _find_input(bsdf, "Roughness")
    metallic = _find_input(bsdf, "Metallic")
    info.roughness = float(roughness.default_value) if roughness is not None else 0.5
    info.metallic = float(metallic.default_value) if metallic is not None else 0.0
    rough_image, rough_channel = _image_channel(roughness)
    metal_image, metal_channel = _image_channel(metallic)
    surface_image = rough_image or metal_image
    if surface_image is not None:
        info.surface_image = surface_image
        info.roughness_channel = rough_channel if rough_image is surface_image else -1
        info.metallic_channel = metal_channel if metal_image is surface_image else -1
        if material.get(COURSE_SURFACE_TAG[0]) == COURSE_SURFACE_TAG[1]:
            # The course's files: specular in blue, shininess in green (docs/materials.md).
            info.surface_convention = "COURSE"
            info.roughness_channel, info.metallic_channel = 1, 2
    specular = _find_input(bsdf, *compat.PRINCIPLED_SPECULAR_INPUTS)
    info.specular_level = float(specular.default_value) \
        if specular is not None and not specular.is_linked else 0.5
    # Principled v2 (Specular IOR Level) reflects by its IOR; v1's IOR is for transmission
    # only and its Specular 0.5 is 4% reflectance, which IOR 1.5 gives.
    ior = _find_input(bsdf, "IOR")
    if specular is not None and specular.name == compat.PRINCIPLED_SPECULAR_INPUTS[0] and \
            ior is not None and not ior.is_linked:
        info.ior = max(float(ior.default_value), 1.0)
    _coat(info, bsdf)
    _emission(info, _find_input(bsdf, *compat.PRINCIPLED_EMISSION_INPUTS),
              _find_input(bsdf, "Emission Strength"))
    normal = _find_input(bsdf, "Normal")
    if normal is not None and normal.is_linked:
        node = normal.links[0].from_node
        if node.type == 'NORMAL_MAP' and node.space == 'TANGENT':
            normal_image, _ = _upstream_image(_find_input(node, "Color"))
            if normal_image is not None:
                info.normal_image = normal_image
                info.normal_strength = float(_find_input(node, "Strength").default_value)
                info.tangent_uv = node.uv_map or ""
    _alpha(info, material, _find_input(bsdf, "Alpha"))
    return info


def _coat(info, bsdf):
    """Principled v2's Coat (Weight, Roughness, IOR; factors). v1's Clearcoat is another
    model and is not read."""
    weight = _find_input(bsdf, "Coat Weight")
    if weight is None or weight.is_linked or weight.default_value <= 0.0:
        return
    info.coat_weight = min(float(weight.default_value), 1.0)
    roughness = _find_input(bsdf, "Coat Roughness")
    if roughness is not None and not roughness.is_linked:
        info.coat_roughness = float(roughness.default_value)
    ior = _find_input(bsdf, "Coat IOR")
    if ior is not None and not ior.is_linked:
        info.coat_ior = max(float(ior.default_value), 1.0)


def _alpha(info, material, alpha_socket):
    """Alpha as EEVEE draws it: constant alpha counts, an image's alpha when linked."""
    if alpha_socket is not None and not alpha_socket.is_linked:
        info.base_color = info.base_color[:3] + (float(alpha_socket.default_value),)
    has_alpha = alpha_socket is not None and \
        (alpha_socket.is_linked or alpha_socket.default_value < 1.0)
    mode = compat.material_alpha_mode(material)
    threshold = float(getattr(material, "alpha_threshold", 0.5))
    if mode == 'HASHED':
        cutoff = _mask_cutoff(alpha_socket)
        if cutoff is not None:     # a glTF mask (4.2+): a cut-out at its cutoff (Sponza)
            mode, threshold = 'CLIP', cutoff
    if not has_alpha:
        mode = 'OPAQUE'
    shadow = compat.material_shadow_mode(material, mode)
    if shadow != 'NONE' and not has_alpha:
        shadow = 'OPAQUE'
    info.alpha_mode = mode
    info.shadow_mode = shadow
    info.alpha_cutoff = threshold if 'CLIP' in (mode, shadow) else 0.0


def memo_material_info(memo, material):
    """``material_info`` once per material and sync: slots sharing a material share one
    MaterialInfo (and so one uniform buffer on the GPU)."""
    key = material.as_pointer() if material is not None else 0
    info = memo.get(key)
    if info is None:
        info = memo[key] = material_info(material)
    return info
