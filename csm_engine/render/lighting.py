"""The lighting pass: one full-screen pass reading the G-buffer, the shadow atlas and the
AO into the target (``lighting_frag.glsl``), with the debug views.

Owns the choice of lighting program for a frame (``lighting_program``) and its draw
(``draw_lighting``), including the background where the G-buffer shows none.
"""

from . import shaders
from .overlays import draw_frozen_cascades

# The lighting program of each Shadow Filter setting (shaders.py builds one per filter).
LIGHTING_PROGRAMS = {"HARD": "lighting_hard", "PCF": "lighting", "SOFT": "lighting_soft",
                     "EXACT": "lighting_exact"}


def lighting_program(snap, emission=False, coat=False, hashed=False):
    """The lighting program for this frame: its Shadow Filter's, with the point- and
    spot-light loops only when the scene has such lights, the G-buffer's emission and
    metallic target read only when some material of the frame writes it (``emission``),
    its coat target only when some material has a coat (``coat``), the World's spherical
    harmonics evaluated only for an environment World, PCF's partial-caster mask read only
    when some shadow caster is alpha-hashed (``hashed``), PCF's tap patterns only when
    the frame uses one (a pattern, or Radius 0's one hard tap), and the debug views only
    when one is shown (shaders.py: llvmpipe pays for code a frame does not use)."""
    settings = snap.settings
    debug = settings.debug_view != "NONE" or bool(settings.debug_inset)
    point_shadows = bool(snap.points) and snap.points[0].casts_shadow
    pcf = settings.shadow_filter == "PCF"
    patterns = pcf and (settings.pcf_pattern != "GRID" or settings.pcf_radius < 1)
    return (LIGHTING_PROGRAMS.get(settings.shadow_filter, "lighting") +
            ("_points" if snap.points else "") +
            ("_point_shadows" if point_shadows else "") + ("_spots" if snap.spots else "") +
            ("_coat" if coat else "_emission" if emission else "") +
            ("_environment" if snap.world_sh is not None else "") +
            ("_hashed" if hashed and pcf else "") + ("_patterns" if patterns else "") +
            ("_debug" if debug else ""))


def draw_lighting(targets, snap, plan, frame_ubo, gbuffer, atlas, ambient_occlusion,
                  target_fb, width, height, depth_tested=False, overlays=True,
                  passes=False, volume_count=None, emission=False, coat=False,
                  hashed=False):
    """Shade ``gbuffer`` (``gbuffer.GBuffer``) with the shadow ``atlas``
    (``shadow_atlas.ShadowAtlas``) and ``ambient_occlusion`` (its ``AmbientOcclusion`` or
    None) into ``target_fb`` (None: the bound framebuffer). ``depth_tested``: the target
    has the G-buffer's depth attached. ``overlays``: then draw ``plan``'s frozen
    cascades. ``passes``: draw with the PASSES programs, which also write the light and
    colour passes into ``target_fb``'s colour slots 2.. (``passes.LIGHTING_PASS_TARGETS``).
    ``volume_count``: the shadow-volume pass's count (``shadow_volumes``), for Filter Exact
    and the Shadow error view. ``emission``, ``coat``: the G-buffer's emission and
    metallic target, its coat target, hold what some material wrote (else zeros, which the
    program then does not read: ``lighting_program``). ``hashed``: some shadow caster is
    alpha-hashed (else the atlas's partial-caster mask is clear)."""
    import gpu
    library = shaders.LIBRARY
    program = lighting_program(snap, emission, coat, hashed)
    debug = program.endswith("_debug")
    suffix = "_passes" if passes else ""
    lighting = library.get(program + suffix)
    # NOTE: with the G-buffer's depth attached to the target (``depth_tested``), the
    # lighting pass runs only where a surface is (its triangle lies on the far plane:
    # depth test GREATER), and a trivial program gives the background its colour (LESS
    # or EQUAL): llvmpipe skips the shading of pixel blocks that fail an early depth
    # test, so sky pixels stop paying for the whole lighting shader. The debug views
    # draw the shadow map over the background too, so they keep the plain pass.
    depth_tested = depth_tested and not debug
    ao_texture = targets.white() if ambient_occlusion is None else ambient_occlusion.texture

    def light_pass():
        gpu.state.viewport_set(0, 0, width, height)
        gpu.state.depth_mask_set(False)
        if depth_tested:
            background = library.get("background" + suffix)
            gpu.state.depth_test_set('LESS_EQUAL')
            background.bind()
            background.uniform_block("frame", frame_ubo)
            targets.call(targets.fullscreen_batch().draw, background)
            gpu.state.depth_test_set('GREATER')
        else:
            gpu.state.depth_test_set('NONE')
        lighting.bind()
        lighting.uniform_block("frame", frame_ubo)
        lighting.uniform_sampler("gbuffer_surface_target", gbuffer.surface)
        lighting.uniform_sampler("gbuffer_depth", gbuffer.view_depth)
        lighting.uniform_sampler("shadow_atlas", atlas.depth)
        lighting.uniform_sampler("shadow_partial", atlas.partial)
        lighting.uniform_sampler("shadow_nearest_blocks", targets.white()
                                 if atlas.nearest_blocks is None else atlas.nearest_blocks)
        lighting.uniform_sampler("ambient_occlusion", ao_texture)
        lighting.uniform_sampler("gbuffer_emission", gbuffer.emission)
        lighting.uniform_sampler("shadow_volume_count",
                                 targets.white() if volume_count is None else volume_count)
        lighting.uniform_sampler("bsdf_lut", targets.bsdf_lut())
        lighting.uniform_sampler("gbuffer_coat", gbuffer.coat)
        targets.call(targets.fullscreen_batch().draw, lighting)
        gpu.state.depth_test_set('NONE')
        if overlays and plan.frozen_camera is not None:
            draw_frozen_cascades(snap, plan)

    if target_fb is None:
        light_pass()
    else:
        with target_fb.bind():
            light_pass()
