"""Anti-aliasing: FXAA over the viewport's lit image, and a final render's FXAA or
jittered samples averaged into a running mean.

Owns ``draw_viewport_fxaa`` and ``draw_antialiased``, which drive ``Pipeline.draw`` for
each sample with a snapshot of their own (the jittered camera and sample index; the
caller's snapshot is never changed), and the frozen-cascade overlays after anti-aliasing,
so 1-pixel lines stay crisp. Sample offsets and weights come from core/antialiasing.py.
A final render's FXAA runs in three passes (``_draw_final_fxaa``) so that only pixel blocks
with an edge run the edge walk; the viewport's in one, into Blender's framebuffer.
"""

import dataclasses
import time
from typing import NamedTuple

from ..core.antialiasing import jittered, sample_offsets
from . import shaders
from .overlays import draw_frozen_cascades, draw_overlays
from .readback import read_target


class Antialiased(NamedTuple):
    plan: object            # the shadow plan of the first sample, shared by the others
    combined_fb: object     # holds the Combined image in colour slot 0
    timings: dict           # the samples' passes summed, plus "fxaa" or "antialiasing"
    passes: object          # PassCounts summed over the samples


def draw_viewport_fxaa(pipeline, snap, cache, width, height):
    """A viewport frame into the bound framebuffer through FXAA: the lit image goes to an
    offscreen target first, and FXAA writes it to the screen. Returns the plan."""
    import gpu
    targets = pipeline.targets
    blend = gpu.state.blend_get() if hasattr(gpu.state, "blend_get") else 'NONE'
    lit = targets.texture("lit", (width, height), 'RGBA16F')
    lit_fb = targets.framebuffer("lit", depth=targets.gbuffer_depth(width, height),
                                 colors=(lit,))
    gpu.state.blend_set('NONE')
    plan = pipeline.draw(snap, cache, lit_fb, width, height, overlays=False,
                         depth_tested=True)
    t = time.perf_counter()
    shader = shaders.LIBRARY.get("fxaa")
    gpu.state.viewport_set(0, 0, width, height)
    gpu.state.depth_test_set('NONE')
    gpu.state.blend_set(blend)
    shader.bind()
    shader.uniform_sampler("source", lit)
    targets.call(targets.fullscreen_batch().draw, shader)
    pipeline.timings["fxaa"] = time.perf_counter() - t
    if plan.frozen_camera is not None:
        draw_frozen_cascades(snap, plan)
    return plan


def draw_antialiased(pipeline, snap, cache, samples, use_fxaa, color, aux, request=None,
                     pass_textures=()):
    """Final-render anti-aliasing into ``color`` (Combined) and ``aux`` (the auxiliary
    passes): FXAA on one sample, or ``samples`` jittered frames averaged into a running
    mean. Sample 0 is unjittered and writes ``aux``; later samples reuse its shadow plan,
    so the shadow maps are drawn once. The light and colour passes (``pass_textures``) are
    averaged like Combined, and every sample gives its Cryptomatte IDs when ``request``
    (``passes.PassRequest``) asks for them. Returns ``Antialiased``."""
    targets = pipeline.targets
    width, height = snap.camera.width, snap.camera.height
    lit = targets.texture("lit_final", (width, height), 'RGBA32F')
    depth = targets.gbuffer_depth(width, height)
    first_fb = targets.framebuffer("lit_first_passes" if pass_textures else "lit_first",
                                   depth=depth, colors=(lit, aux) + tuple(pass_textures))
    offsets, weights = sample_offsets(samples, snap.pixel_filter_width) if not use_fxaa \
        else (None, (1.0,))
    started = time.perf_counter()
    plan = pipeline.draw(snap, cache, first_fb, width, height, overlays=False,
                         depth_tested=True, passes=request,
                         lighting_passes=bool(pass_textures), sample_weight=weights[0])
    passes = pipeline.last_frame
    timings = dict(pipeline.timings)
    if request is not None and "Normal" in request.names and not use_fxaa:
        # Like Depth and Position, the Normal pass is the unjittered sample's.
        pipeline.first_sample_normals = read_target(pipeline.gbuffer_fb, 1, width, height, 4)
    color_fb = targets.framebuffer("final_color_only", colors=(color,))
    t = time.perf_counter()
    if use_fxaa:
        _draw_final_fxaa(targets, lit, color, width, height)
        draw_overlays(snap, plan, color_fb, width, height)
        timings["fxaa"] = time.perf_counter() - t
        timings["total"] = timings.get("total", 0.0) + timings["fxaa"]
        return Antialiased(plan, color_fb, timings, passes)
    # A running mean ping-pongs between the final colour target and a second one.
    spare = targets.texture("accumulate", (width, height), 'RGBA32F')
    spare_fb = targets.framebuffer("accumulate", colors=(spare,))
    scratch_aux = targets.texture("lit_aux_scratch", (width, height), 'RGBA32F')
    scratch_passes = tuple(targets.texture(f"{index}_pass_sample", (width, height), 'RGBA32F')
                           for index in range(len(pass_textures)))
    sample_fb = targets.framebuffer("lit_sample_passes" if pass_textures else "lit_sample",
                                    depth=depth, colors=(lit, scratch_aux) + scratch_passes)
    targets.fullscreen_pass("accumulate", color_fb, width, height,
                            (("previous", lit), ("current", lit)), (("sample_share", 1.0),))
    accumulating = time.perf_counter() - t
    mean, mean_fb, other, other_fb = color, color_fb, spare, spare_fb
    total = weights[0]
    for index, (offset, weight) in enumerate(zip(offsets[1:], weights[1:]), start=1):
        sample = dataclasses.replace(snap, camera=jittered(snap.camera, offset),
                                     sample_index=index)
        pipeline.draw(sample, cache, sample_fb, width, height, plan=plan, overlays=False,
                      depth_tested=True, passes=request, lighting_passes=bool(pass_textures),
                      sample_weight=weight)
        passes = passes + pipeline.last_frame
        for name, value in pipeline.timings.items():
            if name != "total":
                timings[name] = timings.get(name, 0.0) + value
        total += weight
        t = time.perf_counter()
        targets.fullscreen_pass("accumulate", other_fb, width, height,
                                (("previous", mean), ("current", lit)),
                                (("sample_share", float(weight / total)),))
        for slot, (mean_pass, sample_pass) in enumerate(zip(pass_textures, scratch_passes)):
            _accumulate_in_place(targets, slot, mean_pass, sample_pass,
                                 float(weight / total), width, height)
        accumulating += time.perf_counter() - t
        mean, mean_fb, other, other_fb = other, other_fb, mean, mean_fb
    # The samples' own passes are added into shadow/gbuffer/lighting above; this step
    # is the averaging alone.
    timings["antialiasing"] = accumulating
    timings["total"] = time.perf_counter() - started
    draw_overlays(snap, plan, mean_fb, width, height)
    return Antialiased(plan, mean_fb, timings, passes)


def _draw_final_fxaa(targets, lit, color, width, height):
    """FXAA from ``lit`` into ``color`` in three passes (fxaa_frag.glsl): a copy of every
    pixel with its luma into a target of its own; the mark, depth 0 on edge pixels (depth
    only); and the blend, the edge walk under a depth test, so llvmpipe shades only the
    pixel blocks that hold an edge pixel. The same pixels as the one-pass program."""
    luma = targets.texture("fxaa_luma", (width, height), 'R32F')
    mask = targets.texture("fxaa_mask", (width, height), 'DEPTH_COMPONENT32F')
    targets.fullscreen_pass("fxaa_luma", targets.framebuffer("fxaa_luma", colors=(color, luma)),
                            width, height, (("source", lit),))
    targets.fullscreen_pass("fxaa_mark", targets.framebuffer("fxaa_mark", depth=mask),
                            width, height, (("luma", luma),), depth="MARK")
    targets.fullscreen_pass("fxaa_blend",
                            targets.framebuffer("fxaa_blend", depth=mask, colors=(color,)),
                            width, height, (("luma", luma), ("source", lit)), depth="MASKED")


def _accumulate_in_place(targets, slot, mean, sample, share, width, height):
    """Move render pass ``slot``'s running mean ``mean`` towards ``sample`` by ``share``,
    through a spare target (one cannot be read and written in one pass), so the passes stay
    in the targets the final framebuffer reads."""
    spare = targets.texture("accumulate_pass", (width, height), 'RGBA32F')
    spare_fb = targets.framebuffer("accumulate_pass", colors=(spare,))
    targets.fullscreen_pass("accumulate", spare_fb, width, height,
                            (("previous", mean), ("current", sample)), (("sample_share", share),))
    mean_fb = targets.framebuffer(f"accumulate_pass_{slot}", colors=(mean,))
    targets.fullscreen_pass("accumulate", mean_fb, width, height,
                            (("previous", spare), ("current", spare)), (("sample_share", 1.0),))
