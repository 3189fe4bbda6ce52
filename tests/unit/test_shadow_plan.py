"""Shadow planning is a pure function of a frame snapshot (``csm_engine.core.shadow_plan``):
cascades and spot tiles planned, packed into one atlas, and the uniform block filled, all
without Blender or a GPU."""
import math

import numpy as np
import pytest

from csm_engine.core import shadow_plan
from csm_engine.core.camera import CameraProjection, CameraView
from csm_engine.core.frame import FrameSnapshot, PointLight, SpotLight, Sun
from csm_engine.core.frame_layout import FRAME_LAYOUT
from csm_engine.core.settings_model import default_settings

# The model's defaults, except what these tests were written against: the plain fit over
# clip start .. far (no G-buffer here), no AO, a thin blend band and slope bias 1.
SETTINGS = dict(slope_bias=1.0, blend_band=0.1, fit_to_visible=False, ambient_occlusion=False,
                ao_distance=0.0, ao_strength=0.0)


def _snapshot(**overrides):
    world_from_view = np.eye(4)
    world_from_view[:3, 3] = (0.0, -30.0, 5.0)
    world_from_view[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]     # looking along +Y
    projection = CameraProjection(fov_y=math.radians(50), aspect=16 / 9, clip_start=0.1,
                                  clip_end=120.0)
    camera = CameraView(world_from_view, projection.clip_from_view(), 320, 180)
    settings = default_settings(**dict(SETTINGS, **overrides))
    sun = Sun(to_light=np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93]),
              color=np.ones(3), casts_shadow=True)
    return FrameSnapshot(camera=camera, settings=settings, sun=sun, scene_name="plan_test")


BOUNDS = (np.array([-60.0, -60.0, 0.0]), np.array([60.0, 60.0, 12.0]))


def test_three_cascades_of_halving_resolution_cover_the_camera_range():
    plan = shadow_plan.plan_shadows(_snapshot(), BOUNDS)
    assert plan.cascade_count == 3
    assert [t.resolution for t in plan.tiles] == [2048, 1024, 512]
    assert plan.splits[0] == pytest.approx(0.1) and plan.splits[-1] == pytest.approx(120.0)
    assert np.all(np.diff(plan.splits) > 0)
    texels = [t.texel_world for t in plan.tiles]
    assert texels == sorted(texels), "far cascades cover more metres per texel"
    assert plan.warnings == []


def test_atlas_packs_tiles_without_overlap():
    snap = _snapshot(equal_resolution=True, cascade_count=4)
    plan = shadow_plan.plan_shadows(snap, BOUNDS)
    width, height = shadow_plan.layout_atlas(plan.tiles)
    assert width <= shadow_plan.MAX_ATLAS_WIDTH
    boxes = [(t.origin[0], t.origin[1], t.resolution) for t in plan.tiles]
    for i, (x, y, size) in enumerate(boxes):
        assert x + size <= width and y + size <= height
        for (x2, y2, size2) in boxes[i + 1:]:
            assert x + size <= x2 or x2 + size2 <= x or y + size <= y2 or y2 + size2 <= y


def _shadowed_spot_above():
    """A shadow-casting spot light 10 units above the origin, pointing down."""
    world_from_light = np.eye(4)
    world_from_light[:3, 3] = (0.0, 0.0, 10.0)
    return SpotLight(position=np.array([0.0, 0.0, 10.0]), direction=np.array([0.0, 0.0, -1.0]),
                     color=np.ones(3), radius=30.0, spot_size=math.radians(60),
                     spot_blend=0.1, casts_shadow=True, world_from_light=world_from_light,
                     clip_start=0.1)


def test_impossible_manual_splits_fall_back_to_hybrid_with_a_warning():
    plan = shadow_plan.plan_shadows(
        _snapshot(split_scheme="MANUAL", manual_splits=(0.5, 0.2, 0.6)), BOUNDS)
    assert plan.cascade_count == 3
    assert any("hybrid" in w for w in plan.warnings), plan.warnings


def test_no_sun_shadow_means_no_cascades_but_spot_tiles_still_planned():
    snap = _snapshot()
    snap.sun.casts_shadow = False
    snap.spots.append(_shadowed_spot_above())
    plan = shadow_plan.plan_shadows(snap, BOUNDS)
    assert plan.cascade_count == 0
    assert len(plan.tiles) == 1 and plan.tiles[0].is_perspective
    assert plan.spot_tiles == {0: 0}


def test_pack_frame_fills_exactly_the_layout():
    snap = _snapshot()
    plan = shadow_plan.plan_shadows(snap, BOUNDS)
    shadow_plan.layout_atlas(plan.tiles)
    data = shadow_plan.pack_frame(snap, plan)
    assert data.dtype == np.float32
    assert data.nbytes == FRAME_LAYOUT.new_data().nbytes
    assert data.nbytes % 16 == 0, "std140 blocks are whole vec4s"
    assert np.all(np.isfinite(data))


def test_a_frame_packed_from_the_gbuffer_plan_repacks_to_the_same_bytes():
    """Fit to Visible Depth packs a frame twice: first from ``gbuffer_plan`` (no cascades;
    the G-buffer reads only the camera), then from the fitted plan ``like`` the first. The
    second block must equal a fresh pack of the fitted plan, spot lights' tiles included."""
    snap = _snapshot(fit_to_visible=True)
    world_from_light = np.eye(4)
    world_from_light[:3, 3] = (0.0, 0.0, 10.0)
    for x in (-5.0, 5.0):
        snap.spots.append(SpotLight(position=np.array([x, 0.0, 10.0]),
                                    direction=np.array([0.0, 0.0, -1.0]), color=np.ones(3),
                                    radius=30.0, spot_size=math.radians(60), spot_blend=0.1,
                                    casts_shadow=x > 0, world_from_light=world_from_light,
                                    clip_start=0.1))
    first_plan = shadow_plan.gbuffer_plan(snap, BOUNDS)
    assert first_plan.tiles == [] and first_plan.cascade_count == 0
    first = shadow_plan.pack_frame(snap, first_plan)
    plan = shadow_plan.plan_shadows(snap, BOUNDS)
    shadow_plan.layout_atlas(plan.tiles)
    # Bytes, not values: int fields (a spot's shadow tile -1) read as float are NaN.
    assert shadow_plan.pack_frame(snap, plan, like=first).tobytes() == \
        shadow_plan.pack_frame(snap, plan).tobytes()
    # a block of the snapshot alone (what a Fit to Visible Depth G-buffer draws with)
    alone = shadow_plan.pack_frame(snap, None)
    assert shadow_plan.pack_frame(snap, plan, like=alone).tobytes() == \
        shadow_plan.pack_frame(snap, plan).tobytes()
    # and back: a block with more tiles repacked from a plan with fewer leaves no rows
    full = shadow_plan.pack_frame(snap, plan)
    assert shadow_plan.pack_frame(snap, first_plan, like=full).tobytes() == first.tobytes()


def test_the_fitted_range_is_split_with_its_own_lambda():
    """Lambda weighs clip start .. shadow distance; Lambda (Fitted) the depth the G-buffer
    shows (Fit to Visible Depth), whose near end is a surface: each moves only its own
    splits, and both follow the hybrid formula over their range."""
    pairs = np.empty((9, 16, 2))
    pairs[..., 0], pairs[..., 1] = 20.0, 100.0                   # what the view shows
    blocks = shadow_plan.depth_blocks_from_reduction(pairs, 16, 320, 180)

    def splits(**settings):
        return shadow_plan.plan_shadows(_snapshot(**settings), BOUNDS, blocks).splits

    fitted = splits(fit_to_visible=True, fitted_split_lambda=1.0, split_lambda=0.0)
    near, far = fitted[0], fitted[-1]
    assert near <= 20.0 < 100.0 <= far < 120.0
    # Logarithmic over the fitted range, whatever Lambda says.
    assert fitted[1] == pytest.approx(near * (far / near) ** (1 / 3), rel=1e-6)
    assert np.allclose(fitted, splits(fit_to_visible=True, fitted_split_lambda=1.0,
                                      split_lambda=1.0))
    uniform = splits(fit_to_visible=True, fitted_split_lambda=0.0)
    assert uniform[1] == pytest.approx(near + (far - near) / 3, rel=1e-6)
    # Without the fit, Lambda over clip start .. far clip, and Lambda (Fitted) is not read.
    plain = splits(fit_to_visible=False, split_lambda=0.0, fitted_split_lambda=1.0)
    assert plain[0] == pytest.approx(0.1) and plain[1] == pytest.approx(0.1 + 119.9 / 3)


@pytest.mark.parametrize("viewport", [False, True])
@pytest.mark.parametrize("to_light", [(0.3, -0.2, 0.93), (0.0, 0.0, 1.0), (-0.7, 0.6, 0.2),
                                      (0.05, 0.99, 0.1)])
def test_sun_cascades_project_with_w_exactly_one(to_light, viewport):
    """The lighting pass takes a sun cascade's last row as (0, 0, 0, 1), so its lookup's w
    as exactly 1 (lighting_frag.glsl's add_sun): any other bits would move its shadows."""
    snap = _snapshot(cascade_count=4, stabilize=viewport)
    direction = np.array(to_light) / np.linalg.norm(to_light)
    snap.sun = Sun(to_light=direction, color=np.ones(3), casts_shadow=True)
    snap.is_viewport = viewport
    plan = shadow_plan.plan_shadows(snap, BOUNDS)
    shadow_plan.layout_atlas(plan.tiles)
    frame = FRAME_LAYOUT.unpack(shadow_plan.pack_frame(snap, plan))
    assert plan.cascade_count == 4
    for tile in frame["shadow_tiles"][:plan.cascade_count]:
        assert tile["is_perspective"] == 0
        assert tile["shadow_from_world"][3].tolist() == [0.0, 0.0, 0.0, 1.0]


def test_spot_and_point_light_tiles_pack_as_perspective():
    """The lighting pass takes every spot and point-light tile as perspective
    (lighting_frag.glsl): the orthographic lookup would put their shadows elsewhere."""
    snap = _snapshot()
    snap.spots.append(_shadowed_spot_above())
    snap.points.append(PointLight(np.array([2.0, 1.0, 3.0]), np.ones(3), 20.0,
                                  casts_shadow=True))
    plan = shadow_plan.plan_shadows(snap, BOUNDS)
    shadow_plan.layout_atlas(plan.tiles)
    frame = FRAME_LAYOUT.unpack(shadow_plan.pack_frame(snap, plan))
    lights = frame["shadow_tiles"][plan.cascade_count:len(plan.tiles)]
    assert len(lights) == 1 + 6
    assert [int(tile["is_perspective"]) for tile in lights] == [1] * 7
