"""What a frame draws, per instance, ready for the passes: draw lists and instance arrays.

Owns ``MeshDraws`` (one mesh's batches, split by the programs that draw them), the
``DrawMaterial`` of each material slot (uniform block, textures, the keys a kept shadow
tile or G-buffer records of it), ``DrawLists`` (what the passes derive from one frame's
draws), ``InstanceArrays`` (world matrices and bounds) and ``HeldDrawLists``, which keeps
all of them from one frame to the next while the meshes, materials and textures are the
same. Reads the ``MeshCache``'s GPU meshes and textures; draws nothing.
"""

from typing import NamedTuple

import numpy as np

from ..core import cascades
from ..core.material_layout import pack_material
from ..core.shadow_plan import instance_bounds
from .gpu_mesh import MaterialInfo
from .instancing import available, column_major_f32


# Whether each GPU mesh upload (by its serial, never reused) is a closed solid wound
# outward (``closed_outward``): asked by every G-buffer that draws it, answered once.
_CLOSED_SOLIDS = {}
_CLOSED_SOLIDS_MAX = 4096
# NOTE: the check costs ~0.6 us a triangle, once per upload; below this many triangles
# the back faces it would cull cost the G-buffer too little to pay for it.
SOLID_CHECK_MIN_TRIANGLES = 50_000


def closed_outward(mesh):
    """Whether ``mesh`` (a GPUMesh of at least ``SOLID_CHECK_MIN_TRIANGLES``) is a closed
    solid wound outward: its corners welded by position, every edge of its (non-degenerate)
    triangles is used by exactly two of them, once each way, and its signed volume is
    positive. Seen from outside such a solid, every surface in front is a front face, so
    the G-buffer may cull back faces there without changing a pixel (on a geometry-bound
    mesh llvmpipe then rasterizes half the triangles)."""
    if mesh is None or mesh.triangle_count < SOLID_CHECK_MIN_TRIANGLES:
        return False
    held = _CLOSED_SOLIDS.get(mesh.serial)
    if held is None:
        held = _closed_outward(mesh.positions, mesh.triangles)
        if len(_CLOSED_SOLIDS) >= _CLOSED_SOLIDS_MAX:
            _CLOSED_SOLIDS.clear()
        _CLOSED_SOLIDS[mesh.serial] = held
    return held


def _closed_outward(positions, triangles):
    if positions is None or triangles is None or not len(triangles):
        return False
    positions = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
    corners = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    # Welded by the bytes of each position (a GPU mesh splits corners at UV seams and
    # sharp edges; -0.0 and 0.0 stay apart, which can only make the answer no).
    welded = np.unique(positions.view(np.dtype((np.void, 12))).ravel(),
                       return_inverse=True)[1].ravel()
    starts = welded[corners]
    ends = np.roll(starts, -1, axis=1)
    kept = np.all(starts != ends, axis=1)        # degenerate triangles cover nothing
    starts, ends = starts[kept], ends[kept]
    count = int(welded.max()) + 1
    forward = np.sort((starts * count + ends).ravel())
    if not len(forward) or np.any(forward[1:] == forward[:-1]):
        return False        # an edge used twice the same way: not one consistent surface
    if not np.array_equal(forward, np.sort((ends * count + starts).ravel())):
        return False        # an edge without its twin the other way: an open border
    p = positions.astype(np.float64)
    a, b, c = (p[corners[:, k]] - p[0] for k in range(3))
    return bool(np.einsum("ij,ij->", a, np.cross(b, c)) > 0.0)


def column_major(matrix):
    return np.asarray(matrix, dtype=np.float32).T.ravel().tolist()


def column_major_stack(matrices):
    """(N, 4, 4) matrices -> N lists of 16 floats in GLSL's column-major order."""
    return column_major_f32(matrices).tolist()


class InstanceArrays:
    """Per-instance arrays of one frame, kept while the instances are the same (viewport
    redraws that only move the view): world matrices (N, 4, 4), the same in GLSL's
    column-major float32 (``world_from_objects_f32``, (N, 16); as lists of 16 floats:
    ``world_from_objects_gl``, made when first asked for), which are mirrored, the world AABBs (``instance_bounds``) and, for the last sun
    rotation culled against, the boxes in its frame (``cascades.boxes_in_light_frame``),
    and the G-buffer's last texture of instanced matrices (``gbuffer_matrices``: the
    instances it holds, in order, and the texture), so an unmoved view uploads none."""
    __slots__ = ("keys", "meshes", "matrix_bytes", "world_from_objects",
                 "world_from_objects_f32", "_world_from_objects_gl", "mirrored", "bounds_lo_hi", "bounds_checked",
                 "light_frame_boxes", "gbuffer_matrices")

    def __init__(self, snap, cache, keys, meshes, world_from_objects):
        self.keys, self.meshes = keys, meshes
        self.world_from_objects = world_from_objects
        self.matrix_bytes = world_from_objects.tobytes()
        # A row's tolist() is a draw's push constant, rows of it the instanced draws'
        # texture.
        self.world_from_objects_f32 = column_major_f32(world_from_objects)
        self._world_from_objects_gl = None
        # Negative scale turns a triangle's winding around: back-face culling of a mirrored
        # instance culls its front-wound faces.
        self.mirrored = np.linalg.det(world_from_objects[:, :3, :3]) < 0.0
        self.bounds_lo_hi = _instance_bounds(snap, cache, meshes, world_from_objects)
        # Checked once here, not again for every cascade's culling (``shadow_atlas``).
        self.bounds_checked = self.bounds_lo_hi is not None and \
            cascades.boxes_are_valid(*self.bounds_lo_hi)
        self.light_frame_boxes = (None, None)     # (rotation bytes, boxes in its frame)
        self.gbuffer_matrices = (None, None)      # (instance rows' bytes, texture)

    @property
    def world_from_objects_gl(self):
        """The world matrices as N lists of 16 floats (GLSL's column-major order)."""
        if self._world_from_objects_gl is None:
            self._world_from_objects_gl = self.world_from_objects_f32.tolist()
        return self._world_from_objects_gl

    def holds(self, keys, meshes, world_from_objects):
        """Whether these arrays are those of ``keys`` drawn with ``meshes`` (GPUMesh or
        None per instance: a re-upload is a new object, so new bounds) at these matrices."""
        return (keys == self.keys and len(meshes) == len(self.meshes)
                and all(a is b for a, b in zip(meshes, self.meshes))
                and world_from_objects.tobytes() == self.matrix_bytes)

    @property
    def scene_bounds(self):
        """(lo, hi) of every instance's world AABB, or None without instances."""
        if self.bounds_lo_hi is None:
            return None
        return self.bounds_lo_hi[0].min(axis=0), self.bounds_lo_hi[1].max(axis=0)


def _instance_bounds(snap, cache, meshes, world_from_objects):
    """``shadow_plan.instance_bounds`` with the frame's matrices and each mesh's box
    looked up once per mesh, not once per copy; the same arithmetic, so the same bounds."""
    if not meshes or any(mesh is None for mesh in meshes):
        return instance_bounds(snap.instances, cache.meshes)
    numbers = {}
    which = np.fromiter((numbers.setdefault(id(mesh), len(numbers)) for mesh in meshes),
                        dtype=np.int64, count=len(meshes))
    unique = {id(mesh): mesh for mesh in meshes}
    lo = np.stack([unique[key].aabb_min for key in numbers])[which]
    hi = np.stack([unique[key].aabb_max for key in numbers])[which]
    pick = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=bool)
    corners = np.where(pick[None], hi[:, None, :], lo[:, None, :])      # (N,8,3)
    world = np.einsum("nij,nkj->nki", world_from_objects[:, :3, :3], corners) + \
        world_from_objects[:, None, :3, 3]
    return world.min(axis=1), world.max(axis=1)


# The G-buffer programs' material samplers, in DrawMaterial.textures order.
MATERIAL_SAMPLERS = ("base_color_texture", "normal_texture", "emission_texture",
                     "surface_texture")


class DrawMaterial:
    """One material slot ready to draw: its uniform buffer, its four textures (white where
    there is none, see MATERIAL_SAMPLERS), alpha and shadow modes, culling, and the keys a
    shadow tile and a kept G-buffer record of it."""
    __slots__ = ("block", "textures", "textured", "writes_emission", "alpha_mode",
                 "shadow_mode", "backface_culling", "backface_culling_shadow", "shadow_key",
                 "gbuffer_key", "name", "writes_coat")

    def __init__(self, block, textures, textured, writes_emission, alpha_mode, shadow_mode,
                 backface_culling, backface_culling_shadow, shadow_key, gbuffer_key,
                 name="", writes_coat=False):
        self.block, self.textures, self.textured = block, textures, textured
        self.writes_emission = writes_emission
        self.writes_coat = writes_coat
        self.alpha_mode, self.shadow_mode = alpha_mode, shadow_mode
        self.backface_culling = backface_culling
        self.backface_culling_shadow = backface_culling_shadow
        self.shadow_key = shadow_key
        self.gbuffer_key = gbuffer_key
        self.name = name            # the material's name (Cryptomatte Material)


class MeshDraws(NamedTuple):
    """One mesh's draws, each a (GPUBatch, DrawMaterial), by the programs that draw them.
    Instances of one mesh share one ``MeshDraws``."""
    textured: list          # camera, opaque, material with images
    masked: list            # camera, alpha-tested (Clip, Hashed)
    shadow_opaque: list     # shadow casters, opaque
    shadow_masked: list     # shadow casters, alpha-tested
    has_tangents: bool      # the mesh's vertices carry tangents (normal maps)
    untextured: list        # camera, opaque, material without images


class GBufferProgram(NamedTuple):
    """One of the G-buffer's draws: the program, the ``MeshDraws`` list it draws, whether
    the mesh must have tangents (None: either), whether it samples the material's
    textures."""
    program: str
    draws: str
    tangents: object
    textured: bool


# The G-buffer's draws in order: opaque before alpha-tested.
# NOTE: llvmpipe samples a texture even where the shader's `if` skips it, so materials
# without images use a program that has no texture reads (about a third of the G-buffer's
# time here); it is given no textures either (four binds per material a frame).
GBUFFER_PROGRAMS = (GBufferProgram("gbuffer_untextured", "untextured", None, False),
                    GBufferProgram("gbuffer", "textured", False, True),
                    GBufferProgram("gbuffer_tangent", "textured", True, True),
                    GBufferProgram("gbuffer_masked", "masked", False, True),
                    GBufferProgram("gbuffer_masked_tangent", "masked", True, True))


class CasterSignature(NamedTuple):
    """What one mesh's shadow depends on besides its matrix: the geometry (``GPUMesh.serial``,
    never reused, unlike ``id()``) and its shadow materials' ``shadow_key``s."""
    serial: int
    material_keys: tuple


def _writes(items, what="writes_emission"):
    """Whether any camera draw of ``items`` needs the G-buffer's emission target (emission,
    metallic or a coat: ``writes_emission``) or its coat target (``writes_coat``).
    Instances of one mesh share their ``MeshDraws``, so each is looked at once."""
    seen = set()
    for entry in items:
        if id(entry) in seen:
            continue
        seen.add(id(entry))
        for draws in (entry.textured, entry.masked, entry.untextured):
            for _batch, material in draws:
                if getattr(material, what):
                    return True
    return False


class DrawLists:
    """What the passes derive from one frame's ``MeshDraws`` per instance (``items``), kept
    with them: the same items give the same answers. Per instance: whether each of
    GBUFFER_PROGRAMS and each shadow program (opaque, alpha-masked) draws it, and which
    ``MeshDraws`` it shares with other instances (``groups``: an int per instance, the
    same for instances drawn by the same batches and materials). ``instancing``: the
    passes draw a group's copies in one instanced draw (``render/instancing.py``)."""
    __slots__ = ("items", "writes_emission", "gbuffer_masks", "shadow_masks", "partial_mask",
                 "signatures", "groups", "instancing", "writes_coat")

    def __init__(self, items, instancing=True):
        self.items = items
        self.instancing = instancing
        numbers = {}
        self.groups = np.fromiter((numbers.setdefault(id(entry), len(numbers))
                                   for entry in items), dtype=np.int64, count=len(items))
        self.writes_emission = _writes(items)
        self.writes_coat = _writes(items, "writes_coat")
        self.gbuffer_masks = tuple(
            np.array([bool(getattr(entry, program.draws)) and
                      (program.tangents is None or entry.has_tangents == program.tangents)
                      for entry in items], dtype=bool)
            for program in GBUFFER_PROGRAMS)
        self.shadow_masks = tuple(np.array([bool(draws) for draws in column], dtype=bool)
                                  for column in ([entry.shadow_opaque for entry in items],
                                                 [entry.shadow_masked for entry in items]))
        # Which instances have an alpha-hashed shadow material (the atlas's partial-caster
        # mask draws only those).
        self.partial_mask = np.array([any(material.shadow_mode == 'HASHED'
                                          for _batch, material in entry.shadow_masked)
                                      for entry in items], dtype=bool)
        # Per instance: CasterSignature, or None when a masked draw reads an image (see
        # HeldDrawLists.caster_signatures); made when the shadow pass first asks.
        self.signatures = None


def _same_textures(cache, textures):
    """Whether the mesh cache still gives each image of ``textures`` ((image, GPU texture
    or False) pairs) the texture it gave when they were recorded."""
    try:
        return all(cache.textures.get(image.name) is texture for image, texture in textures)
    except ReferenceError:      # an image removed since
        return False


class HeldDrawLists:
    """One view's draw lists and instance arrays, kept from the frame before while they
    would come out the same.

    ``instancing``: whether copies of a mesh draw in one instanced draw per pass (where
    Blender can, ``instancing.available``); tests turn it off to compare with one draw per
    object."""

    instancing = True

    def __init__(self):
        self._instances = None      # InstanceArrays of the last frame
        self._draws = None          # the last frame's MeshDraws and what they came from
        self._lists = None          # DrawLists of the last frame's MeshDraws
        self._signatures = {}       # instance key -> (MeshDraws, CasterSignature or None)
        # Slots without a material draw as Blender's default grey. Its uniform block lives
        # with this view, never in module state: a GPU object still alive when Python
        # exits is freed after the GPU context is gone, which crashes.
        self._default_material = MaterialInfo()

    def instances(self, snap, cache):
        """This frame's ``InstanceArrays``: the last frame's when the instances, their
        meshes and matrices are the same, else new ones."""
        instances = snap.instances
        keys = tuple(i.key for i in instances)
        meshes = [cache.meshes.get(key) for key in keys]
        world_from_objects = np.array([i.world_from_object for i in instances],
                                      dtype=np.float64).reshape(-1, 4, 4)
        held = self._instances
        if held is None or not held.holds(keys, meshes, world_from_objects):
            held = self._instances = InstanceArrays(snap, cache, keys, meshes,
                                                    world_from_objects)
        return held

    def lists(self, snap, cache, white):
        """This frame's ``DrawLists`` (``white``: the texture for slots without an image)."""
        items = self._kept_draw_items(snap, cache, white)
        instancing = bool(self.instancing) and available()
        if self._lists is None or self._lists.items is not items or \
                self._lists.instancing != instancing:
            self._lists = DrawLists(items, instancing)
        return self._lists

    def caster_signatures(self, snap, cache, lists):
        """Per instance, its ``CasterSignature``; None when a masked draw reads an image,
        which never equals a held signature: the image may have been edited in place.
        Asked for once per ``DrawLists``."""
        if lists.signatures is not None:
            return lists.signatures
        per_key = {}
        signatures = []
        # A mesh's signature is kept with its draw lists: the same lists (the same object)
        # have the same signature.
        held = self._signatures
        kept = {}
        for instance, entry in zip(snap.instances, lists.items):
            if instance.key not in per_key:
                known = held.get(instance.key)
                if known is not None and known[0] is entry:
                    signature = known[1]
                else:
                    mesh = cache.meshes.get(instance.key)
                    keys = tuple(material.shadow_key for _b, material in
                                 entry.shadow_opaque + entry.shadow_masked)
                    signature = CasterSignature(mesh.serial if mesh is not None else 0, keys)
                    if None in keys:
                        signature = None
                per_key[instance.key] = signature
                kept[instance.key] = (entry, signature)
            signatures.append(per_key[instance.key])
        self._signatures = kept
        lists.signatures = signatures
        return signatures

    def _kept_draw_items(self, snap, cache, white):
        """``_draw_items``, kept from the last frame while it would come out the same: the
        same meshes (a re-upload is a new GPUMesh), the same MaterialInfo lists (a material
        edit makes new ones, see MeshCache.sync) and, for every image, the same GPU texture
        (an edited image's texture is dropped from the cache)."""
        keys = tuple(instance.key for instance in snap.instances)
        held = self._draws
        if held is not None and held[0] == keys and held[1] is white and \
                all(cache.meshes.get(key) is mesh and
                    (mesh is None or mesh.materials is materials)
                    for key, mesh, materials in held[2]) and _same_textures(cache, held[3]):
            return held[4]
        items = _draw_items(snap, cache, white, self._default_material)
        meshes = [(key, cache.meshes.get(key)) for key in dict.fromkeys(keys)]
        textures = tuple((image, cache.textures.get(image.name))
                         for _key, mesh in meshes if mesh is not None
                         for info in mesh.materials
                         for image in (info.image, info.normal_image, info.emission_image,
                                       info.surface_image)
                         if image is not None)
        self._draws = (keys, white, [(key, mesh, mesh.materials if mesh is not None
                                      else None) for key, mesh in meshes],
                       textures, items)
        return items


def _draw_items(snap, cache, white, default_material):
    """Per instance, its mesh's ``MeshDraws``. Instances of one mesh share them (also
    objects of their own whose meshes were uploaded once, e.g. linked duplicates: the same
    upload and the same materials), and slots of one material share its ``DrawMaterial``
    (so the G-buffer binds a material shared by many objects once)."""
    per_key = {}
    per_mesh = {}
    per_material = {}
    items = []
    for instance in snap.instances:
        entry = per_key.get(instance.key)
        if entry is None:
            mesh = cache.meshes.get(instance.key)
            # The same upload drawn with the same MaterialInfo objects draws the same.
            shared = None if mesh is None else \
                (mesh.serial, tuple(map(id, mesh.materials)))
            entry = per_mesh.get(shared) if shared is not None else None
            if entry is not None:
                per_key[instance.key] = entry
                items.append(entry)
                continue
            entry = MeshDraws([], [], [], [], bool(mesh is not None and mesh.has_tangents), [])
            for batch, slot in (mesh.batches if mesh is not None else ()):
                material = _material(cache, mesh, slot, white, default_material,
                                     per_material)
                camera = entry.masked if material.alpha_mode != 'OPAQUE' else \
                    (entry.textured if material.textured else entry.untextured)
                camera.append((batch, material))
                if material.shadow_mode != 'NONE':
                    shadow = entry.shadow_opaque if material.shadow_mode == 'OPAQUE' \
                        else entry.shadow_masked
                    shadow.append((batch, material))
            per_key[instance.key] = entry
            if shared is not None:
                per_mesh[shared] = entry
        items.append(entry)
    return items


def _material(cache, mesh, slot, white, default_material, memo=None):
    """One material slot as both the shadow and G-buffer passes draw it: its uniform
    block (made once per MaterialInfo and set of loadable textures, kept on it),
    textures (white where there is none) and settings."""
    import gpu
    material = mesh.materials[slot] if slot < len(mesh.materials) else None
    if material is None:
        material = default_material
    if memo is not None:
        # Keyed by identity: MaterialInfo objects live in the meshes' lists meanwhile.
        held = memo.get(id(material))
        if held is None:
            held = memo[id(material)] = _material(cache, mesh, slot, white,
                                                  default_material)
        return held
    images = (material.image, material.normal_image, material.emission_image,
              material.surface_image)
    textures = tuple(cache.texture(image) if image is not None else None
                     for image in images)
    loaded = tuple(texture is not None for texture in textures)
    held = material.gpu_block
    if held is None or held[0] != loaded:
        shadow_alpha = material.shadow_mode if material.shadow_mode in \
            ('CLIP', 'HASHED') else 'OPAQUE'
        block = pack_material({
            "base_color": material.base_color, "emission": material.emission,
            "metallic": material.metallic, "roughness": material.roughness,
            "specular_level": material.specular_level, "ior": material.ior,
            "coat_weight": material.coat_weight, "coat_roughness": material.coat_roughness,
            "coat_ior": material.coat_ior,
            "normal_strength": material.normal_strength,
            "alpha_cutoff": material.alpha_cutoff, "alpha_mode": material.alpha_mode,
            "shadow_alpha_mode": shadow_alpha,
            "has_base_texture": int(loaded[0]), "has_normal_texture": int(loaded[1]),
            "has_emission_texture": int(loaded[2]),
            "surface_convention": material.surface_convention,
            "roughness_channel": material.roughness_channel if loaded[3] else -1,
            "metallic_channel": material.metallic_channel if loaded[3] else -1})
        held = (loaded, gpu.types.GPUUniformBuf(block.tobytes()), shadow_alpha,
                block.tobytes())
        material.gpu_block = held
    # What a shadow tile drawn with this material depends on; None when it reads an
    # image, which may have been edited in place.
    shadow_key = (held[2], material.base_color[3], material.alpha_cutoff,
                  material.backface_culling_shadow)
    if held[2] != 'OPAQUE' and loaded[0]:
        shadow_key = None
    writes_emission = bool(loaded[2] or max(material.emission) > 0.0 or
                           material.metallic > 0.0 or material.coat_weight > 0.0 or
                           (loaded[3] and material.metallic_channel >= 0))
    # What a G-buffer drawn with this material depends on; None when it reads an
    # image (painted or reloaded in place, it keeps its name and texture).
    gbuffer_key = None if any(loaded) else \
        (held[3], material.alpha_mode, material.backface_culling)
    return DrawMaterial(held[1], tuple(t or white for t in textures), any(loaded),
                        writes_emission, material.alpha_mode, material.shadow_mode,
                        material.backface_culling, material.backface_culling_shadow,
                        shadow_key, gbuffer_key, material.name, material.coat_weight > 0.0)
