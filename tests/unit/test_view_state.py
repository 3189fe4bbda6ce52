"""Each view plans its shadows with its own ``ShadowViewState``: two views of one scene
(two viewports, or a viewport and the final render) never see each other's frozen
cascades or Fit to Visible Depth hysteresis.

Each frame is planned as the pipeline plans it: ``gbuffer_plan`` first, then
``plan_shadows`` with the G-buffer's depth blocks, both with the view's state.
"""
import dataclasses
import math

import numpy as np

from csm_engine.core import shadow_plan
from csm_engine.core.camera import CameraProjection, CameraView
from csm_engine.core.frame import FrameSnapshot, Sun
from csm_engine.core.settings_model import default_settings
from csm_engine.core.view_state import ShadowViewState
from tests.unit.test_shadow_plan import BOUNDS, SETTINGS

WIDTH, HEIGHT, BLOCK = 320, 180, 16


def _snapshot(camera_x=0.0, camera_y=-30.0, scene_name="two_views", **overrides):
    world_from_view = np.eye(4)
    world_from_view[:3, 3] = (camera_x, camera_y, 5.0)
    world_from_view[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]     # looking along +Y
    projection = CameraProjection(fov_y=math.radians(50), aspect=WIDTH / HEIGHT,
                                  clip_start=0.1, clip_end=120.0)
    camera = CameraView(world_from_view, projection.clip_from_view(), WIDTH, HEIGHT)
    settings = default_settings(**dict(SETTINGS, fit_to_visible=True, **overrides))
    sun = Sun(to_light=np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93]),
              color=np.ones(3), casts_shadow=True)
    return FrameSnapshot(camera=camera, settings=settings, sun=sun, scene_name=scene_name,
                         is_viewport=True)


def _blocks(nearest, farthest):
    """Depth blocks of a view that shows surfaces from ``nearest`` to ``farthest`` (view
    depth), the near ones at the bottom of the screen."""
    rows, cols = math.ceil(HEIGHT / BLOCK), math.ceil(WIDTH / BLOCK)
    pairs = np.empty((rows, cols, 2))
    ramp = np.linspace(nearest, farthest, rows + 1)
    pairs[..., 0] = ramp[:-1, None]
    pairs[..., 1] = ramp[1:, None]
    return shadow_plan.depth_blocks_from_reduction(pairs, BLOCK, WIDTH, HEIGHT)


def _frame(state, snap, blocks):
    """One Fit to Visible Depth frame of a view, as the pipeline plans it."""
    shadow_plan.gbuffer_plan(snap, BOUNDS, state)
    return shadow_plan.plan_shadows(snap, BOUNDS, blocks, view_state=state)


def _drawn(plan):
    """Everything the passes draw with: splits, bands and every tile's matrix."""
    return (plan.splits.tobytes(), plan.bands.tobytes(),
            tuple(tile.clip_from_world.tobytes() for tile in plan.tiles))


# View B moves a little between its two frames; view A looks at the scene from elsewhere
# and sees a wider depth range that holds B's (so a shared hysteresis would keep A's).
B_FRAMES = ((_snapshot(), _blocks(20.0, 100.0)),
            (_snapshot(camera_x=0.3, camera_y=-29.8), _blocks(21.0, 98.0)))
A_FRAME = (_snapshot(camera_x=25.0, camera_y=-45.0), _blocks(17.0, 115.0))


def _view_b_second_frame(between=None, freeze=False):
    """View B's second plan, with view A planned in between on ``between`` (a state, or
    None for no view A)."""
    frames = [(snap if not freeze else _with(snap, freeze_cascades=True), blocks)
              for snap, blocks in B_FRAMES]
    state_b = ShadowViewState()
    _frame(state_b, *frames[0])
    if between is not None:
        snap_a, blocks_a = A_FRAME
        _frame(state_b if between == "shared" else between,
               _with(snap_a, freeze_cascades=freeze), blocks_a)
    return _frame(state_b, *frames[1])


def _with(snap, **settings):
    return dataclasses.replace(snap, settings=dataclasses.replace(snap.settings, **settings))


def test_fit_to_visible_hysteresis_is_per_view():
    alone = _view_b_second_frame()
    beside = _view_b_second_frame(between=ShadowViewState())
    assert _drawn(beside) == _drawn(alone)
    # The check can fail: sharing B's state with A (as one module-level state did) makes
    # B hold A's depth range.
    assert _drawn(_view_b_second_frame(between="shared")) != _drawn(alone)


def test_frozen_cascades_are_per_view():
    alone = _view_b_second_frame(freeze=True)
    first_b = _frame(ShadowViewState(), _with(B_FRAMES[0][0], freeze_cascades=True),
                     B_FRAMES[0][1])
    assert _drawn(alone) == _drawn(first_b), "B keeps the cascades of its first frame"
    assert alone.frozen_camera is B_FRAMES[0][0].camera
    state_a = ShadowViewState()
    beside = _view_b_second_frame(between=state_a, freeze=True)
    assert _drawn(beside) == _drawn(alone)
    assert state_a.frozen.camera is A_FRAME[0].camera, "A froze its own cascades"
    # and A draws its own, not B's: a state shared with B (as one module-level state was)
    # hands A the cascades B froze for its own camera.
    snap_a = _with(A_FRAME[0], freeze_cascades=True)
    a_alone = _frame(ShadowViewState(), snap_a, A_FRAME[1])
    shared = ShadowViewState()
    _frame(shared, _with(B_FRAMES[0][0], freeze_cascades=True), B_FRAMES[0][1])
    assert _drawn(_frame(shared, snap_a, A_FRAME[1])) == _drawn(first_b) != _drawn(a_alone)


def test_without_a_view_state_nothing_is_held_or_frozen():
    snap, blocks = B_FRAMES[1]
    fresh = shadow_plan.plan_shadows(snap, BOUNDS, blocks, view_state=ShadowViewState())
    _frame(None, *A_FRAME)
    assert _drawn(shadow_plan.plan_shadows(snap, BOUNDS, blocks)) == _drawn(fresh)
    frozen = _with(snap, freeze_cascades=True)
    shadow_plan.plan_shadows(_with(A_FRAME[0], freeze_cascades=True), BOUNDS, A_FRAME[1])
    assert _drawn(shadow_plan.plan_shadows(frozen, BOUNDS, blocks)) == _drawn(fresh)


def test_a_view_that_shows_another_scene_starts_afresh():
    state = ShadowViewState()
    snap, blocks = B_FRAMES[0]
    _frame(state, _with(snap, freeze_cascades=True), blocks)
    other = FrameSnapshot(**{**vars(_with(A_FRAME[0], freeze_cascades=True)),
                             "scene_name": "another"})
    plan = _frame(state, other, A_FRAME[1])
    assert plan.frozen_camera is other.camera
    assert _drawn(plan) == _drawn(_frame(ShadowViewState(), other, A_FRAME[1]))


def _final(snap, frame):
    return dataclasses.replace(snap, is_viewport=False, frame=frame)


def test_a_final_render_depends_on_its_own_frame_alone_and_keeps_boxes_over_a_small_move():
    """Any render before (another frame, another view, a far camera) leaves a final
    render's plan as in a process that rendered nothing before (a farm's worker renders
    any frame to the pixels ``-a`` gives it); the next frame of a slow camera move gets
    most of its boxes again (quantized, not held)."""
    (first, first_blocks), (moved, moved_blocks) = B_FRAMES
    snap_a, blocks_a = A_FRAME
    fresh = _frame(ShadowViewState(), _final(moved, 2), moved_blocks)
    state = ShadowViewState()
    for snap, blocks in ((first, first_blocks), (snap_a, blocks_a), (moved, moved_blocks)):
        _frame(state, _final(snap, 1), blocks)
        assert _drawn(_frame(state, _final(moved, 2), moved_blocks)) == _drawn(fresh)
    # A camera 2 cm on (a slow camera animation's next frame): the same depth blocks.
    near = _snapshot(camera_x=0.02, camera_y=-29.99)
    kept = [a.clip_from_world.tobytes() == b.clip_from_world.tobytes()
            for a, b in zip(_frame(state, _final(first, 1), first_blocks).tiles,
                            _frame(state, _final(near, 2), first_blocks).tiles)]
    assert sum(kept) >= 2, kept
    # The check can fail: a viewport that holds its boxes plans the moved frame
    # differently from a fresh one.
    viewport = ShadowViewState()
    _frame(viewport, first, first_blocks)
    assert _drawn(_frame(viewport, near, first_blocks)) != \
        _drawn(_frame(ShadowViewState(), near, first_blocks))
