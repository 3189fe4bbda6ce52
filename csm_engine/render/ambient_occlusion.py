"""The ambient-occlusion pass: a half-resolution horizon search over the G-buffer and a
separable depth-aware blur (``ao_frag.glsl``), which the lighting pass brings to full
resolution.

Owns the half-resolution AO targets (a depth target saying which pixels have something to
search, which the search and the blur are tested against; the search's arcs, depth and
normal; the blur's row sums; the blurred AO and depth) and the record of what the blurred
one holds (the frame cache's ``ambient_occlusion``): with the G-buffer kept from the frame
before and the same AO inputs, the AO drawn then is kept too. Off (or at strength or
distance 0), nothing is allocated or drawn.
"""

from typing import NamedTuple

from ..core.frame_layout import FRAME_LAYOUT
from .gbuffer import programs_key
from .resources import HeldAmbientOcclusion

# What the AO passes read of the frame block besides the G-buffer (ao_frag.glsl).
_AO_FRAME_FIELDS = ("ao_enabled", "ao_distance", "ao_strength", "ao_pixels_per_unit",
                    "ao_view_ray", "is_perspective", "viewport_size", "view_from_world")


class AmbientOcclusion(NamedTuple):
    texture: object         # half resolution, RG: AO (1 open, 0 occluded), view depth
    framebuffer: object
    kept: bool              # the one drawn for the G-buffer kept from the frame before


def draw_ambient_occlusion(targets, snap, frame_ubo, frame_data, gbuffer, gbuffer_kept,
                           width, height):
    """The AO of ``gbuffer`` (``gbuffer.GBuffer``: its view depth and normals) with the
    frame block ``frame_ubo`` (``frame_data`` as numpy); None when AO is off."""
    settings = snap.settings
    if not settings.ambient_occlusion or settings.ao_strength <= 0.0 or \
            settings.ao_distance <= 0.0:
        return None
    half_size = ((width + 1) // 2, (height + 1) // 2)
    sums = targets.texture("ao_sums", half_size, 'RGBA32F')
    rows = targets.texture("ao_rows", half_size, 'RGBA32F')
    blurred = targets.texture("ao", half_size, 'RG32F')
    searched = targets.texture("ao_searched", half_size, 'DEPTH_COMPONENT32F')
    inputs = (programs_key(), FRAME_LAYOUT.field_bytes(frame_data, _AO_FRAME_FIELDS))
    frame_cache = targets.frame_cache
    held = frame_cache.ambient_occlusion
    if gbuffer_kept and held is not None and held.texture is blurred and \
            held.inputs == inputs:
        blurred_fb = targets.framebuffer("ao", depth=searched, colors=(blurred,))
        return AmbientOcclusion(blurred, blurred_fb, True)
    frame_cache.ambient_occlusion = None
    # NOTE: the mask writes depth 1 where there is nothing to search (background, or the
    # whole distance inside the pixel) and 0 elsewhere; the search and both blur passes
    # are depth-tested against it (their triangle lies at depth 1: GREATER), so llvmpipe
    # skips the blocks without a search instead of running them masked. What they skip
    # keeps the cleared values: "nothing" for the search's and the rows' sums (depth 0,
    # which the blur leaves out) and "open, background" (AO 1, depth 0) for the result,
    # which the lighting pass reads as open.
    mask_fb = targets.framebuffer("ao_mask", depth=searched)
    search_fb = targets.framebuffer("ao_search", depth=searched, colors=(sums,))
    rows_fb = targets.framebuffer("ao_rows", depth=searched, colors=(rows,))
    blurred_fb = targets.framebuffer("ao", depth=searched, colors=(blurred,))
    for fb, cleared in ((search_fb, (0.0, 0.0, 0.0, 0.0)), (rows_fb, (0.0, 0.0, 0.0, 0.0)),
                        (blurred_fb, (1.0, 0.0, 0.0, 0.0))):
        with fb.bind():
            targets.call(fb.clear, color=cleared)
    depth = (("gbuffer_depth", gbuffer.view_depth),)
    for program, fb, samplers, mode in (
            ("ao_mask", mask_fb, depth, "MARK"),
            ("ao", search_fb, depth + (("gbuffer_surface_target", gbuffer.surface),), "MASKED"),
            ("ao_blur_rows", rows_fb, (("ao_half", sums),), "MASKED"),
            ("ao_blur", blurred_fb, (("ao_half", rows),), "MASKED")):
        targets.fullscreen_pass(program, fb, half_size[0], half_size[1], samplers,
                                blocks=(("frame", frame_ubo),), depth=mode)
    if targets.records:
        frame_cache.ambient_occlusion = HeldAmbientOcclusion(blurred, inputs)
    return AmbientOcclusion(blurred, blurred_fb, False)
