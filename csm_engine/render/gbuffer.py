"""The G-buffer pass: what the camera sees, per pixel, for the lighting pass to shade.

Owns the G-buffer's targets (``GBuffer``): two packed ones (``gbuffer_layout.glsl``):
base colour, specular, shading normal and the triangle's own normal (facet) in one, view
depth (0 = background), roughness and the object's Shadow Terminator Geometry Offset in the
other; then emission+metallic, coat, depth and, for Cryptomatte passes only, each pixel's
object, material and asset IDs (render/passes.py); materials are one uniform block each
(core/material_layout.py). World positions are rebuilt from view depth where needed
(``core.camera.world_positions``). Also owns ``GBufferContents``: what a G-buffer drawn now
would hold, so that one the targets already hold is not drawn again (F12 after a shadow or
light setting changed; an unchanged re-render; a viewport redraw of an unmoved view), and
``seen_from_outside``: the big closed solids the camera sees from outside, whose back faces
are culled (hidden behind their front faces; on llvmpipe a geometry-bound mesh then costs
about half).
"""

from typing import NamedTuple

import numpy as np

from ..core.frame_layout import FRAME_LAYOUT
from ..core.shadow_plan import front_to_back
from . import instancing, passes, shaders
from .draw_lists import GBUFFER_PROGRAMS, MATERIAL_SAMPLERS, closed_outward
from .resources import HeldGBuffer

# What the G-buffer programs read of the frame block (gbuffer_vert/frag.glsl).
_GBUFFER_FRAME_FIELDS = ("clip_from_world", "camera_position", "camera_forward",
                         "sample_index")


class GBuffer(NamedTuple):
    surface: object         # base colour, specular, normals (gbuffer_layout.glsl)
    view_depth: object      # view depth, roughness, terminator offset (likewise)
    emission: object
    depth: object
    framebuffer: object
    coat: object = None
    ids: object = None      # Cryptomatte IDs (object, material, asset, 1), when asked for


class GBufferContents(NamedTuple):
    """What a G-buffer holds: the programs, camera and sample (``camera``), and which
    instances in which order at which matrices, each one's geometry and material inputs,
    and Shadow Terminator Geometry Offsets. A record of the camera alone stands for a
    viewport G-buffer drawn while the view moved (see ``gbuffer_contents``)."""
    camera: tuple
    order: bytes = None
    matrices: bytes = None
    draws: tuple = None
    terminator_offsets: bytes = None


def programs_key():
    """Which compiled programs a frame draws with (F5 replaces them), compiled now if they
    were not yet, so a record made with it names the programs that drew it."""
    library = shaders.LIBRARY
    library.get("gbuffer")
    return id(library), library.generation


def draw_gbuffer(targets, snap, cache, lists, instances, frame_ubo, frame_data, width,
                 height, ids=None):
    """Draw the camera's view of ``lists`` (``DrawLists``) at ``instances``' matrices
    (``InstanceArrays``) into the G-buffer targets, near to far, with the frame block
    ``frame_ubo`` (``frame_data`` as numpy). Keeps the targets as they are when they hold
    what it would draw (the frame cache's ``gbuffer``). ``ids`` (``passes.DrawIds``): also
    write the Cryptomatte IDs, with the CRYPTOMATTE programs into one more target (such a
    G-buffer is always drawn, never kept). Returns (``GBuffer``, whether it was kept)."""
    surface = targets.texture("surface", (width, height), 'RGBA32F')
    view_depth = targets.texture("view_depth", (width, height), 'RG32F')
    depth = targets.gbuffer_depth(width, height)
    emission = targets.texture("emission", (width, height), 'RGBA16F')
    coat = targets.texture("coat", (width, height), 'RGBA16F')
    # Emission and metallic have a target only in frames that draw some, and the coat one
    # only in frames with a coated material (which write emission's too: the outputs are
    # positional): without one each fragment writes one target less (llvmpipe pays per
    # target), and the lighting pass reads a texture kept at zero.
    colors = (surface, view_depth)
    if lists.writes_emission:
        colors += (emission, coat) if lists.writes_coat else (emission,)
    _keep_zero(targets, "zeroed_emission", emission, lists.writes_emission)
    _keep_zero(targets, "zeroed_coat", coat, lists.writes_coat)
    gbuffer_fb = targets.framebuffer(f"gbuffer_{len(colors)}", depth=depth, colors=colors)
    id_target = None
    if ids is not None:
        # Drawn by a second draw into the coat's slot (Blender's framebuffers take six
        # colour targets): the first slots get the same values again.
        id_target = targets.texture("cryptomatte_ids", (width, height), 'RGBA32F')
    gbuffer = GBuffer(surface, view_depth, emission, depth, gbuffer_fb, coat, id_target)
    # Near to far, so the early depth test skips the shading of hidden fragments.
    order = np.asarray(front_to_back(snap, instances.bounds_lo_hi), dtype=np.int64)
    order = order[np.fromiter((i.visible_camera for i in snap.instances), dtype=bool,
                              count=len(snap.instances))[order]]
    order = order[in_view(snap.camera.clip_from_world, instances.bounds_lo_hi, order,
                          len(snap.instances))]
    terminator_offsets = np.fromiter((i.terminator_offset for i in snap.instances),
                                     dtype=np.float64, count=len(snap.instances))
    frame_cache = targets.frame_cache
    drawn_into = (surface, view_depth, emission, depth, coat)
    contents = gbuffer_contents(targets, snap, cache, lists, order,
                                instances.world_from_objects, terminator_offsets, frame_data)
    if ids is not None:
        contents = None
    held = frame_cache.gbuffer
    if targets.records and contents is not None and held is not None and \
            held.contents == contents and \
            all(a is b for a, b in zip(held.targets, drawn_into)):
        return gbuffer, True
    if targets.records:
        frame_cache.forget_gbuffer()
    # Cryptomatte frames draw every copy on its own in both draws, so that the second
    # draw's depths equal the first's and its depth test (LESS_EQUAL) passes where the
    # first draw's surfaces are.
    solids = seen_from_outside(snap.camera, instances)
    _draw(targets, lists, instances, order, terminator_offsets, frame_ubo, gbuffer_fb,
          width, height, instancing_allowed=ids is None, solids=solids)
    if ids is not None:
        # Background pixels keep no IDs of an earlier sample.
        clear_fb = targets.framebuffer("gbuffer_ids_clear", colors=(id_target,))
        with clear_fb.bind():
            targets.call(clear_fb.clear, color=(0.0, 0.0, 0.0, 0.0))
        ids_fb = targets.framebuffer("gbuffer_ids", depth=depth,
                                     colors=(surface, view_depth, emission, id_target))
        _draw(targets, lists, instances, order, terminator_offsets, frame_ubo, ids_fb,
              width, height, ids, instancing_allowed=False, clear=False, solids=solids)
    if contents is not None and targets.records:
        frame_cache.gbuffer = HeldGBuffer(drawn_into, contents)
    return gbuffer, False


def in_view(clip_from_world, bounds_lo_hi, rows, count):
    """Which of ``rows`` (instance indices) have a world box that may reach the view:
    a box whose 8 corners all lie beyond one plane of the view frustum (x, y or z outside
    -w..w in clip space) cannot draw a pixel. Only the others are drawn, and only their
    matrices uploaded."""
    rows = np.asarray(rows, dtype=np.int64)
    if bounds_lo_hi is None or len(bounds_lo_hi[0]) != count or not len(rows):
        return np.ones(len(rows), dtype=bool)
    lo, hi = bounds_lo_hi[0][rows], bounds_lo_hi[1][rows]
    m = np.asarray(clip_from_world, dtype=np.float64)
    inside = np.ones(len(rows), dtype=bool)
    for axis in range(3):
        # x <= w and x >= -w are the planes (w - x) >= 0 and (w + x) >= 0, linear in the
        # corner: a box's greatest value picks hi or lo per axis by the plane's sign.
        for plane in (m[3] - m[axis], m[3] + m[axis]):
            greatest = np.where(plane[:3] >= 0.0, hi, lo) @ plane[:3] + plane[3]
            inside &= greatest >= 0.0
    return inside


def _keep_zero(targets, marker, texture, written):
    """Clear ``texture`` to zero once when this frame does not write it (``marker``: the
    ``Targets`` attribute naming the texture last cleared)."""
    if written:
        setattr(targets, marker, None)
    elif getattr(targets, marker) is not texture:
        fb = targets.framebuffer(f"{marker}_clear", colors=(texture,))
        with fb.bind():
            targets.call(fb.clear, color=(0.0, 0.0, 0.0, 0.0))
        setattr(targets, marker, texture)


def seen_from_outside(camera, instances):
    """Per instance: whether its mesh is a closed solid wound outward
    (``draw_lists.closed_outward``) that the camera sees only from outside: a perspective
    camera whose near plane's corners (and so its whole near plane) stay out of the
    instance's world box. Its back faces are then all hidden behind its front faces, and
    the G-buffer culls them."""
    count = len(instances.meshes)
    bounds = instances.bounds_lo_hi
    if not count or bounds is None or not camera.is_perspective:
        return np.zeros(count, dtype=bool)
    left, right, bottom, top = camera.projection.view_window()
    reach = camera.clip_start * float(np.sqrt(1.0 + max(abs(left), abs(right)) ** 2 +
                                              max(abs(bottom), abs(top)) ** 2))
    position = camera.position
    gap = np.maximum(np.maximum(bounds[0] - position, position - bounds[1]), 0.0)
    outside = np.einsum("ij,ij->i", gap, gap) > (1.01 * reach + 1e-6) ** 2
    return outside & np.fromiter((closed_outward(mesh) for mesh in instances.meshes),
                                 dtype=bool, count=count)


def _draw(targets, lists, instances, order, terminator_offsets, frame_ubo, gbuffer_fb,
          width, height, ids=None, instancing_allowed=True, clear=True, solids=None):
    """Draw ``order``'s instances into ``gbuffer_fb``. ``solids``: per instance, whether
    its back faces may be culled (``seen_from_outside``); alpha-masked materials never
    are (their holes show the inside)."""
    import gpu
    items = lists.items
    mirrored = instances.mirrored
    per_program = []
    for program, drawn in zip(GBUFFER_PROGRAMS, lists.gbuffer_masks):
        rows = order[drawn[order]]
        if len(rows):
            per_program.append((program, _program_runs(lists, rows, mirrored,
                                                        terminator_offsets,
                                                        instancing_allowed)))
    matrices = _instanced_matrices(instances, per_program)
    with gbuffer_fb.bind():
        gpu.state.viewport_set(0, 0, width, height)
        if clear:
            targets.call(gbuffer_fb.clear, color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        gpu.state.depth_test_set('LESS_EQUAL')
        gpu.state.depth_mask_set(True)
        state = _DrawState()
        offset = 0      # the next instanced run's first matrix in ``matrices``
        # Opaque before alpha-tested; untextured materials with the program that samples
        # no texture, meshes with tangents (normal maps) with the programs that read them.
        for program, runs in per_program:
            for run in runs:
                index = int(run[0])
                solid = solids is not None and program.draws != "masked" and \
                    bool(solids[run].all())
                if len(run) > 1:
                    shader = state.use(program, True, frame_ubo, False)
                    shader.uniform_sampler("instance_matrices", matrices)
                    shader.uniform_int("instance_offset", offset)
                    offset += len(run)
                else:
                    shader = state.use(program, False, frame_ubo, ids is not None)
                    shader.uniform_float("world_from_object",
                                         instances.world_from_objects_f32[index].tolist())
                    if ids is not None:
                        shader.uniform_float("cryptomatte_object",
                                             float(ids.per_instance[index, 0]))
                        shader.uniform_float("cryptomatte_asset",
                                             float(ids.per_instance[index, 1]))
                # Most objects share Blender's default: set only when it changes.
                if terminator_offsets[index] != state.offset:
                    state.offset = terminator_offsets[index]
                    shader.uniform_float("terminator_offset", float(state.offset))
                for batch, material in getattr(items[index], program.draws):
                    wanted = ('FRONT' if mirrored[index] else 'BACK') \
                        if material.backface_culling or solid else 'NONE'
                    if wanted != state.culling:
                        gpu.state.face_culling_set(wanted)
                        state.culling = wanted
                    if material is not state.bound:
                        shader.uniform_block("material", material.block)
                        if ids is not None:
                            shader.uniform_float("cryptomatte_material",
                                                 passes.material_id(ids, material.name))
                        if program.textured:
                            for name, texture in zip(MATERIAL_SAMPLERS, material.textures):
                                shader.uniform_sampler(name, texture)
                        state.bound = material
                    if len(run) > 1:
                        targets.call(batch.draw_instanced, shader, instance_count=len(run))
                    else:
                        targets.call(batch.draw, shader)
        gpu.state.face_culling_set('NONE')
        gpu.state.depth_test_set('NONE')


class _DrawState:
    """The G-buffer's GL state while it draws: the bound program, material, culling and
    Shadow Terminator Geometry Offset, so each is set only when it changes."""
    __slots__ = ("shader", "bound", "culling", "offset")

    def __init__(self):
        self.shader, self.bound, self.culling, self.offset = None, None, 'NONE', None

    def use(self, program, instanced, frame_ubo, with_ids):
        shader = shaders.LIBRARY.get(program.program + ("_instanced" if instanced else "") +
                                     ("_ids" if with_ids else ""))
        if shader is not self.shader:
            shader.bind()
            shader.uniform_block("frame", frame_ubo)
            # A newly bound program has none of the last one's uniforms.
            self.shader, self.bound, self.offset = shader, None, None
        return shader


def _program_runs(lists, rows, mirrored, terminator_offsets, instancing_allowed=True):
    """One program's rows (near to far) as runs drawn together: copies of one mesh with
    one winding and one Shadow Terminator Geometry Offset. Without instancing (or when
    each copy writes its own Cryptomatte IDs, ``instancing_allowed`` False) every row is a
    run of its own, in order."""
    if not lists.instancing or not instancing_allowed:
        return [rows[i:i + 1] for i in range(len(rows))]
    # The runs' key: the mesh's group, then the winding and the offset (few distinct).
    offsets = np.unique(terminator_offsets, return_inverse=True)[1].ravel()
    keys = (lists.groups * 2 + mirrored) * (int(offsets.max(initial=0)) + 1) + offsets
    return instancing.runs(rows, keys)


def _instanced_matrices(instances, per_program):
    """The texture of the instanced runs' world matrices, in draw order: the one made for
    the same runs before (an unmoved view, a re-render), else a new upload."""
    rows = [run for _program, runs in per_program for run in runs if len(run) > 1]
    if not rows:
        return None
    rows = np.concatenate(rows)
    key = rows.tobytes()
    held = instances.gbuffer_matrices
    if held[0] == key:
        return held[1]
    texture = instancing.matrix_texture(instances.world_from_objects_f32[rows])
    instances.gbuffer_matrices = (key, texture)
    return texture


def gbuffer_contents(targets, snap, cache, lists, order, world_from_objects,
                     terminator_offsets, frame_data):
    """What a G-buffer drawn now would hold (``GBufferContents``), as a value to compare
    with the one the targets hold; None when a draw reads an image (its pixels may have
    changed in place). In the viewport the camera is looked at first, so a redraw of a
    moving view pays for little else (its record holds only the camera, which the next
    redraw of that view completes)."""
    camera = (programs_key(), lists.writes_emission, lists.writes_coat,
              FRAME_LAYOUT.field_bytes(frame_data, _GBUFFER_FRAME_FIELDS))
    held = targets.frame_cache.gbuffer
    # NOTE: the benchmark's Python-only redraw (``benchmark_skip_gpu_calls``) repeats the
    # view of the redraw before; it pays what a redraw of a moving view pays.
    if not targets.records or \
            (snap.is_viewport and (held is None or held.contents.camera != camera)):
        return GBufferContents(camera)
    # Instances of one group share their draws: each group's inputs once, then which group
    # each drawn instance is.
    groups = lists.groups[order]
    unique, first = np.unique(groups, return_index=True)
    per_group = []
    instances = snap.instances
    items = lists.items
    for index in order[first].tolist():
        entry = items[index]
        mesh = cache.meshes.get(instances[index].key)
        keys = tuple(material.gbuffer_key for _batch, material in
                     entry.textured + entry.masked + entry.untextured)
        if None in keys:
            return None
        per_group.append((mesh.serial if mesh is not None else 0, keys))
    draws = (unique.tobytes(), tuple(per_group), groups.tobytes())
    # The facet target carries each object's Shadow Terminator Geometry Offset.
    return GBufferContents(camera, order.tobytes(), world_from_objects[order].tobytes(),
                           draws, terminator_offsets[order].tobytes())
