"""The G-buffer pass: what the camera sees, per pixel, for the lighting pass to shade.

Owns the G-buffer's targets (``GBuffer``): albedo+specular, normal+roughness, view depth
(0 = background), the triangle's own normal+the object's Shadow Terminator Geometry Offset
(facet), emission+metallic, coat, and depth; materials are one uniform block each
(core/material_layout.py). World positions are rebuilt from view depth where needed
(``core.camera.world_positions``). Also owns ``GBufferContents``: what a G-buffer drawn now
would hold, so that one the targets already hold is not drawn again (F12 after a shadow or
light setting changed; an unchanged re-render; a viewport redraw of an unmoved view).
"""

from typing import NamedTuple

import numpy as np

from ..core.frame_layout import FRAME_LAYOUT
from ..core.shadow_plan import front_to_back
from . import shaders
from .draw_lists import GBUFFER_PROGRAMS, MATERIAL_SAMPLERS
from .resources import HeldGBuffer

# What the G-buffer programs read of the frame block (gbuffer_vert/frag.glsl).
_GBUFFER_FRAME_FIELDS = ("clip_from_world", "camera_position", "camera_forward",
                         "sample_index")


class GBuffer(NamedTuple):
    albedo: object
    normal: object
    view_depth: object
    emission: object
    facet: object
    depth: object
    framebuffer: object
    coat: object = None


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
                 height):
    """Draw the camera's view of ``lists`` (``DrawLists``) at ``instances``' matrices
    (``InstanceArrays``) into the G-buffer targets, near to far, with the frame block
    ``frame_ubo`` (``frame_data`` as numpy). Keeps the targets as they are when they hold
    what it would draw (the frame cache's ``gbuffer``). Returns (``GBuffer``, whether it
    was kept)."""
    albedo = targets.texture("albedo", (width, height), 'RGBA16F')
    normal = targets.texture("normal", (width, height), 'RGBA16F')
    view_depth = targets.texture("view_depth", (width, height), 'R32F')
    depth = targets.gbuffer_depth(width, height)
    emission = targets.texture("emission", (width, height), 'RGBA16F')
    facet = targets.texture("facet", (width, height), 'RGBA16F')
    coat = targets.texture("coat", (width, height), 'RGBA16F')
    # Emission and metallic have a target only in frames that draw some, and the coat one
    # only in frames with a coated material (which write emission's too: the outputs are
    # positional): without one each fragment writes a sixth less (llvmpipe: ~15 % of the
    # G-buffer), and the lighting pass reads a texture kept at zero.
    colors = (albedo, normal, view_depth, facet)
    if lists.writes_emission:
        colors += (emission, coat) if lists.writes_coat else (emission,)
    _keep_zero(targets, "zeroed_emission", emission, lists.writes_emission)
    _keep_zero(targets, "zeroed_coat", coat, lists.writes_coat)
    gbuffer_fb = targets.framebuffer(f"gbuffer_{len(colors)}", depth=depth, colors=colors)
    gbuffer = GBuffer(albedo, normal, view_depth, emission, facet, depth, gbuffer_fb, coat)
    # Near to far, so the early depth test skips the shading of hidden fragments.
    order = np.asarray(front_to_back(snap, instances.bounds_lo_hi), dtype=np.int64)
    order = order[np.fromiter((i.visible_camera for i in snap.instances), dtype=bool,
                              count=len(snap.instances))[order]]
    terminator_offsets = np.fromiter((i.terminator_offset for i in snap.instances),
                                     dtype=np.float64, count=len(snap.instances))
    frame_cache = targets.frame_cache
    drawn_into = (albedo, normal, view_depth, emission, depth, facet, coat)
    contents = gbuffer_contents(targets, snap, cache, lists, order,
                                instances.world_from_objects, terminator_offsets, frame_data)
    held = frame_cache.gbuffer
    if targets.records and contents is not None and held is not None and \
            held.contents == contents and \
            all(a is b for a, b in zip(held.targets, drawn_into)):
        return gbuffer, True
    if targets.records:
        frame_cache.forget_gbuffer()
    _draw(targets, lists, instances, order, terminator_offsets, frame_ubo, gbuffer_fb,
          width, height)
    if contents is not None and targets.records:
        frame_cache.gbuffer = HeldGBuffer(drawn_into, contents)
    return gbuffer, False


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


def _draw(targets, lists, instances, order, terminator_offsets, frame_ubo, gbuffer_fb,
          width, height):
    import gpu
    library = shaders.LIBRARY
    items = lists.items
    mirrored = instances.mirrored
    world_from_objects_gl = instances.world_from_objects_gl
    with gbuffer_fb.bind():
        gpu.state.viewport_set(0, 0, width, height)
        targets.call(gbuffer_fb.clear, color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        gpu.state.depth_test_set('LESS_EQUAL')
        gpu.state.depth_mask_set(True)
        culling = 'NONE'
        # Opaque before alpha-tested; untextured materials with the program that samples
        # no texture, meshes with tangents (normal maps) with the programs that read them.
        for program, drawn in zip(GBUFFER_PROGRAMS, lists.gbuffer_masks):
            rows = order[drawn[order]]
            if not len(rows):
                continue
            shader = library.get(program.program)
            shader.bind()
            shader.uniform_block("frame", frame_ubo)
            bound = None
            offset = None
            for index in rows.tolist():
                draws = getattr(items[index], program.draws)
                shader.uniform_float("world_from_object", world_from_objects_gl[index])
                # Most objects share Blender's default: set only when it changes.
                if terminator_offsets[index] != offset:
                    offset = terminator_offsets[index]
                    shader.uniform_float("terminator_offset", float(offset))
                for batch, material in draws:
                    wanted = ('FRONT' if mirrored[index] else 'BACK') \
                        if material.backface_culling else 'NONE'
                    if wanted != culling:
                        gpu.state.face_culling_set(wanted)
                        culling = wanted
                    if material is not bound:
                        shader.uniform_block("material", material.block)
                        if program.textured:
                            for name, texture in zip(MATERIAL_SAMPLERS, material.textures):
                                shader.uniform_sampler(name, texture)
                        bound = material
                    targets.call(batch.draw, shader)
        gpu.state.face_culling_set('NONE')
        gpu.state.depth_test_set('NONE')


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
    per_entry = {}
    draws = []
    instances = snap.instances
    items = lists.items
    for index in order.tolist():
        entry = items[index]
        known = per_entry.get(id(entry))
        if known is None:
            mesh = cache.meshes.get(instances[index].key)
            keys = tuple(material.gbuffer_key for _batch, material in
                         entry.textured + entry.masked + entry.untextured)
            if None in keys:
                return None
            known = per_entry[id(entry)] = (mesh.serial if mesh is not None else 0, keys)
        draws.append(known)
    # The facet target carries each object's Shadow Terminator Geometry Offset.
    return GBufferContents(camera, order.tobytes(), world_from_objects[order].tobytes(),
                           tuple(draws), terminator_offsets[order].tobytes())
