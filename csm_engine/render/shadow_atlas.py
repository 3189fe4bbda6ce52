"""The shadow pass: one depth-only tile per cascade (and per shadowed spot or point light
face) in one atlas, and beside it a one-byte partial-caster mask.

Owns the atlas and mask textures' allocation (``allocate_atlas``), caster culling per tile,
the tiles' draws (a big closed solid wholly beyond a cascade's near plane without its faces
turned away from the light: the depth each texel keeps is the same), and the records of what
each tile holds (``TileSignature`` in the ``FrameCache``): only tiles whose contents would
change are cleared and drawn. The mask is
1 where an alpha-hashed caster lies in front of what a texel holds: its shadow is the share
of texels the filter finds, which PCF Sharpen must leave alone (``lighting_frag.glsl``).
"""

from typing import NamedTuple

import numpy as np

from ..core import cascades
from ..core.shadow_plan import layout_atlas
from . import instancing, shaders
from .draw_lists import closed_outward
from .instancing import column_major_f32
from .resources import AtlasTiles, PartialMarks


# NOTE: a cascade kept from the frame before (core/cascades/holding.py) has the very same
# light matrix; one refitted to the same box may differ in the depth row by rounding: a
# tile is kept when that row moved by at most this (clip units, ~1e-4 mm over a 100 m
# range), far below any depth bias, and compared with the matrix it was drawn with, so it
# cannot drift.
TILE_DEPTH_TOLERANCE = 1e-6


class ShadowAtlas(NamedTuple):
    depth: object           # the atlas (DEPTH_COMPONENT32F)
    partial: object         # the partial-caster mask (R8), the atlas's size
    framebuffer: object     # depth only
    # The soft filter's nearest depth per block (``blocker_search``), None for the others.
    nearest_blocks: object = None


class TileSignature(NamedTuple):
    """What a tile drawn now would hold: compared with what it holds (``same_tile``)."""
    origin: tuple
    resolution: int
    cull_front: bool
    clip_from_world: np.ndarray     # float64 (4, 4): compared with a depth tolerance
    caster_matrices: bytes          # the casters' world matrices
    casters: tuple                  # their CasterSignature (None: never the same)


class TileCounts(NamedTuple):
    drawn: int
    kept: int


def same_tile(held, signature):
    """Whether a tile drawn with ``held`` holds what ``signature`` would draw."""
    if held is None or \
            (held.origin, held.resolution, held.cull_front) != \
            (signature.origin, signature.resolution, signature.cull_front) or \
            held.caster_matrices != signature.caster_matrices or \
            held.casters != signature.casters:
        return False
    a, b = held.clip_from_world, signature.clip_from_world
    # Rows 0, 1 and 3 the same bytes (a -0.0 for a 0.0 only redraws the tile), row 2
    # within the tolerance; bytes of slices cost less than numpy's comparisons here.
    return a[:2].tobytes() == b[:2].tobytes() and a[3].tobytes() == b[3].tobytes() and \
        float(np.abs(a[2] - b[2]).max()) <= TILE_DEPTH_TOLERANCE


def allocate_atlas(targets, plan, warnings):
    """The atlas and its partial-caster mask for ``plan``'s tiles; on allocation failure,
    halve the tiles' resolutions (in ``plan``) and say so in ``warnings``."""
    while True:
        size = layout_atlas(plan.tiles)
        try:
            depth = targets.texture("atlas", size, 'DEPTH_COMPONENT32F')
            partial = targets.texture("atlas_partial", size, 'R8')
            return ShadowAtlas(depth, partial, targets.framebuffer("atlas", depth=depth))
        except Exception as error:
            if all(t.resolution <= 64 for t in plan.tiles):
                raise
            message = (f"shadow atlas {size[0]}x{size[1]} could not be allocated "
                       f"({error}); halving shadow resolutions")
            if message not in warnings:
                warnings.append(message)
            for tile in plan.tiles:
                if tile.resolution > 64:
                    tile.texel_world *= 2.0
                    if tile.texel_world_xy is not None:
                        tile.texel_world_xy = tuple(2.0 * t for t in tile.texel_world_xy)
                tile.resolution = max(tile.resolution // 2, 64)


def _held_tiles(frame_cache, atlas):
    """What each tile of ``atlas`` holds; forgotten when the texture is reallocated."""
    held = frame_cache.atlas_tiles
    if held is None or held.atlas is not atlas:
        held = frame_cache.atlas_tiles = AtlasTiles(atlas, {})
    return held.tiles


def draw_shadow_atlas(targets, snap, plan, atlas, lists, instances, signatures):
    """Draw the tiles of ``plan`` whose contents would change into ``atlas``
    (``ShadowAtlas``): the casters of ``lists`` (``DrawLists``) culled per tile with
    ``instances`` (``InstanceArrays``), and ``signatures`` (per instance
    ``CasterSignature``) to know a tile is unchanged. Updates the frame cache's tile
    records and partial marks. Returns the ``TileCounts``."""
    import gpu
    atlas_fb = atlas.framebuffer
    held = _held_tiles(targets.frame_cache, atlas.depth)
    # Blender 3.4's gpu.state has no scissor: there the whole atlas is cleared and drawn.
    can_clear_tile = hasattr(gpu.state, "scissor_set")
    cull_front = bool(snap.settings.cull_front_faces)
    world_from_objects = instances.world_from_objects
    stale = []
    casts_shadow = np.fromiter((i.casts_shadow for i in snap.instances), dtype=bool,
                               count=len(snap.instances))
    for tile in plan.tiles:
        visible = np.asarray(_cull(snap.instances, instances, tile), dtype=np.int64)
        visible = visible[casts_shadow[visible]]
        signature = TileSignature(tuple(tile.origin), tile.resolution, cull_front,
                                  np.asarray(tile.clip_from_world, dtype=np.float64),
                                  world_from_objects[visible].tobytes(),
                                  tuple(map(signatures.__getitem__, visible.tolist())))
        key = (tuple(tile.origin), tile.resolution)
        if can_clear_tile and None not in signature.casters and \
                same_tile(held.get(key), signature):
            continue
        stale.append((tile, visible, key, signature))
    with atlas_fb.bind():
        if not can_clear_tile:
            targets.call(atlas_fb.clear, depth=1.0)
        gpu.state.depth_test_set('LESS_EQUAL')
        gpu.state.depth_mask_set(True)
        gpu.state.face_culling_set('FRONT' if cull_front else 'NONE')
        for tile, visible, key, signature in stale:
            _begin_tile(targets, atlas_fb, tile, dict(depth=1.0) if can_clear_tile else None)
            if targets.records:
                # Forget the tile's contents while it is redrawn: if drawing raises,
                # the next frame draws it again.
                held.pop(key, None)
            if len(visible):
                _draw_casters(targets, lists, instances, tile, visible, cull_front)
            if targets.records:
                held[key] = signature
        gpu.state.face_culling_set('NONE')
    _draw_partial_mask(targets, lists, instances, atlas, stale, cull_front, can_clear_tile)
    return TileCounts(len(stale), len(plan.tiles) - len(stale))


def _begin_tile(targets, fb, tile, clear=None):
    """Draw into ``tile`` of the bound ``fb`` from now on; with ``clear`` (``fb.clear``'s
    arguments) clear that tile first, and only it."""
    import gpu
    gpu.state.viewport_set(tile.origin[0], tile.origin[1], tile.resolution,
                           tile.resolution)
    if clear:
        # NOTE: a clear honours the scissor box, not the viewport: without it the whole
        # atlas (the other tiles too) would be cleared.
        gpu.state.scissor_test_set(True)
        gpu.state.scissor_set(tile.origin[0], tile.origin[1], tile.resolution,
                              tile.resolution)
        targets.call(fb.clear, **clear)
        gpu.state.scissor_test_set(False)


def _draw_partial_mask(targets, lists, instances, atlas, stale, cull_front, can_clear_tile):
    """The atlas's partial-caster mask for the redrawn tiles ``stale``: cleared, then
    marked by their alpha-hashed casters against the finished depth (depth writes
    off). A scene without hashed casters draws nothing here once the mask is clear."""
    import gpu
    frame_cache = targets.frame_cache
    held = frame_cache.partial_marks
    new = held is None or held.texture is not atlas.partial
    if new:
        held = frame_cache.partial_marks = PartialMarks(atlas.partial, True)
    hashed = bool(lists.partial_mask.any())
    if not hashed and not held.may_hold_marks:
        return
    clear = (0.0, 0.0, 0.0, 0.0)
    partial_fb = targets.framebuffer("atlas_partial", depth=atlas.depth,
                                     colors=(atlas.partial,))
    with partial_fb.bind():
        cleared = new or not hashed or not can_clear_tile
        if cleared:
            targets.call(partial_fb.clear, color=clear)
        held.may_hold_marks = hashed
        if not hashed:
            return
        gpu.state.depth_test_set('LESS_EQUAL')
        gpu.state.depth_mask_set(False)
        gpu.state.face_culling_set('FRONT' if cull_front else 'NONE')
        for tile, visible, _key, _signature in stale:
            _begin_tile(targets, partial_fb, tile, None if cleared else dict(color=clear))
            if len(visible) and lists.partial_mask[visible].any():
                _draw_casters(targets, lists, instances, tile, visible, cull_front,
                              partial_only=True)
        gpu.state.face_culling_set('NONE')
        gpu.state.depth_mask_set(True)


def _draw_casters(targets, lists, instances, tile, visible, cull_front, partial_only=False):
    """Draw the shadow casters ``visible`` (instance indices) into ``tile``: opaque,
    then alpha-masked; copies of one mesh in one instanced draw (``lists.instancing``).
    ``partial_only``: only the alpha-hashed materials of the instances that have some,
    with the partial-caster mask's program."""
    import gpu
    library = shaders.LIBRARY
    items, mirrored = lists.items, instances.mirrored
    # float64 products, then float32: the same values for both kinds of draw.
    clip_from_objects = column_major_f32(tile.clip_from_world @
                                         instances.world_from_objects[visible])
    default = 'FRONT' if cull_front else 'NONE'
    culling = default
    solids = None if cull_front or partial_only else _solids_beyond_near(instances, tile, visible)
    # (program, which instances it draws, their MeshDraws list, whether it reads the
    # material): the partial-caster mask draws only the hashed materials of the masked.
    passes = (("shadow_partial", lists.partial_mask, "shadow_masked", False),) \
        if partial_only else \
        (("shadow", lists.shadow_masks[0], "shadow_opaque", False),
         ("shadow_masked", lists.shadow_masks[1], "shadow_masked", True))
    per_pass = []
    for program, drawn, draws, reads_material in passes:
        rows = np.flatnonzero(drawn[visible])      # positions in ``visible``
        if not len(rows):
            continue
        if lists.instancing:
            # A run: copies of one mesh with one winding (culling may depend on it).
            keys = lists.groups[visible] * 2 + mirrored[visible]
            runs = instancing.runs(rows, keys)
        else:
            runs = [rows[i:i + 1] for i in range(len(rows))]
        per_pass.append((program, draws, reads_material, runs))
    together = [run for *_rest, runs in per_pass for run in runs if len(run) > 1]
    matrices = instancing.matrix_texture(clip_from_objects[np.concatenate(together)]) \
        if together else None
    offset = 0      # the next instanced run's first matrix in ``matrices``
    current = None
    for program, draws, reads_material, runs in per_pass:
        for run in runs:
            row = int(run[0])
            index = int(visible[row])
            instanced = len(run) > 1
            shadow = library.get(program + ("_instanced" if instanced else ""))
            if shadow is not current:
                shadow.bind()
                current, bound = shadow, None
            if instanced:
                shadow.uniform_sampler("instance_matrices", matrices)
                shadow.uniform_int("instance_offset", offset)
                offset += len(run)
            else:
                shadow.uniform_float("clip_from_object", clip_from_objects[row].tolist())
            # A closed solid's faces turned away from the light lie behind its faces
            # toward it: culled, the nearest depth a texel keeps is the same.
            solid = solids is not None and not reads_material and bool(solids[run].all())
            for batch, material in getattr(items[index], draws):
                if partial_only and material.shadow_mode != 'HASHED':
                    continue
                # 4.2+ "Backface Culling" of shadows: the faces turned away from the
                # light (the winding turned around for a mirrored instance).
                wanted = ('FRONT' if mirrored[index] else 'BACK') \
                    if material.backface_culling_shadow or solid else default
                if wanted != culling:
                    gpu.state.face_culling_set(wanted)
                    culling = wanted
                if reads_material and material is not bound:
                    shadow.uniform_block("material", material.block)
                    shadow.uniform_sampler("base_color_texture", material.textures[0])
                    bound = material
                if instanced:
                    targets.call(batch.draw_instanced, shadow, instance_count=len(run))
                else:
                    targets.call(batch.draw, shadow)
    if culling != default:
        gpu.state.face_culling_set(default)


def _solids_beyond_near(instances, tile, visible):
    """Per row of ``visible`` (instance indices): whether it is a closed solid wound
    outward (``draw_lists.closed_outward``) whose world box lies wholly beyond ``tile``'s
    near plane (a sun cascade's), so the light sees it only from outside and its faces
    turned away from the light may be culled; None when there is none."""
    if tile.cascade is None or instances.bounds_lo_hi is None or not len(visible):
        return None
    meshes = instances.meshes
    solid = np.fromiter((closed_outward(meshes[i]) for i in visible.tolist()), dtype=bool,
                        count=len(visible))
    if not solid.any():
        return None
    rows = np.flatnonzero(solid)
    lo, hi = (b[visible[rows]] for b in instances.bounds_lo_hi)
    corners = np.where(_CORNER_PICK[None, :, :], hi[:, None, :], lo[:, None, :])
    depth = corners @ tile.clip_from_world[2, :3] + tile.clip_from_world[2, 3]   # (n, 8)
    solid[rows] = depth.min(axis=1) >= -1.0      # orthographic: clip z = window depth
    return solid


# Which end of a box each of its 8 corners takes per axis (bit a of the index).
_CORNER_PICK = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=bool)
_CORNER_PICK.setflags(write=False)


def _cull(snap_instances, instances, tile):
    """The instances (indices) whose world AABB reaches ``tile``'s light volume."""
    bounds_lo_hi = instances.bounds_lo_hi
    if bounds_lo_hi is None:
        return range(0)
    if tile.point_face is not None:
        position, face, reach = tile.point_face
        return np.nonzero(cascades.aabbs_in_point_light_face(
            bounds_lo_hi[0], bounds_lo_hi[1], position, face, reach))[0]
    if tile.cascade is None:    # spot tiles: no caster culling (few, small frusta)
        return range(len(snap_instances))
    checked = instances.bounds_checked
    rotated = None
    if checked:
        # The cascades of one sun share its rotation: the boxes are turned into its
        # frame once, and again only when the sun turns or the instances change.
        light_from_world = tile.cascade.light_from_world
        rotation = light_from_world[:3, :3].tobytes()
        if instances.light_frame_boxes[0] != rotation:
            instances.light_frame_boxes = (rotation, cascades.boxes_in_light_frame(
                bounds_lo_hi[0], bounds_lo_hi[1], light_from_world))
        rotated = instances.light_frame_boxes[1]
    mask = cascades.aabbs_in_cascade(bounds_lo_hi[0], bounds_lo_hi[1], tile.cascade,
                                     checked=checked, rotated=rotated)
    return np.nonzero(mask)[0]
