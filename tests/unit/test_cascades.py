"""Unit tests for csm_engine/core/cascades/: the cascade math, without Blender.

Run: ./dev test tests/unit/test_cascades.py
"""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from csm_engine.core import cascades as csm

RNG_SEED = 20261107
TOL = 1e-9


# ----------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------

def rotation_matrix(axis, angle):
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                     [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                     [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]])


def world_from_view(rotation, position):
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = position
    return matrix


def random_rotation(rng):
    return rotation_matrix(rng.normal(size=3), rng.uniform(0, 2 * math.pi))


def random_direction(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def random_projection(rng):
    if rng.random() < 0.75:
        return csm.CameraProjection(kind="PERSP", fov_y=rng.uniform(0.2, 2.0),
                                    aspect=rng.uniform(0.5, 2.5),
                                    shift_x=rng.uniform(-0.3, 0.3), shift_y=rng.uniform(-0.3, 0.3),
                                    clip_start=rng.uniform(0.01, 1.0),
                                    clip_end=rng.uniform(20.0, 500.0))
    return csm.CameraProjection(kind="ORTHO", ortho_height=rng.uniform(1.0, 50.0),
                                aspect=rng.uniform(0.5, 2.5),
                                shift_x=rng.uniform(-0.3, 0.3), shift_y=rng.uniform(-0.3, 0.3),
                                clip_start=rng.uniform(0.01, 1.0),
                                clip_end=rng.uniform(20.0, 200.0))


def to_clip(cascade, points):
    points = np.atleast_2d(points)
    homogeneous = np.c_[points, np.ones(len(points))] @ cascade.clip_from_world.T
    return homogeneous[:, :3] / homogeneous[:, 3:]


def texel_coordinates(cascade, points):
    """Where world points land on the shadow map, in texels (x, y)."""
    clip = to_clip(cascade, points)
    return (clip[:, :2] * 0.5 + 0.5) * cascade.resolution


DEFAULT_CAMERA = csm.CameraProjection(kind="PERSP", fov_y=math.radians(50), aspect=16 / 9,
                                      clip_start=0.1, clip_end=200.0)
SUN_DIR = np.array([0.3, 0.4, -0.866])


def default_view(position=(0.0, -20.0, 5.0)):
    # Camera looking along world +Y (its -Z), tilted a little down.
    look = rotation_matrix((1, 0, 0), math.radians(80))
    return world_from_view(look, position)


# ----------------------------------------------------------------------------------------
# split distances
# ----------------------------------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(near=st.floats(1e-3, 100.0), ratio=st.floats(1.01, 1e5),
       count=st.integers(1, 4), scheme=st.sampled_from(["UNIFORM", "LOG", "HYBRID"]),
       lam=st.floats(0.0, 1.0))
def test_splits_increase_and_hit_near_and_far_exactly(near, ratio, count, scheme, lam):
    far = near * ratio
    splits = csm.split_distances(near, far, count, scheme, lam=lam)
    assert splits.shape == (count + 1,)
    assert splits[0] == near and splits[-1] == far
    assert np.all(np.diff(splits) > 0)


@settings(max_examples=200, deadline=None)
@given(near=st.floats(0.0, 10.0), span=st.floats(1.0, 1000.0), count=st.integers(1, 4),
       cuts=st.lists(st.floats(0.01, 0.99), min_size=3, max_size=3, unique=True))
def test_manual_splits_increase_and_hit_near_and_far_exactly(near, span, count, cuts):
    far = near + span
    interior = near + np.sort(cuts)[:count - 1] * span
    # Distinct cuts can still round to one distance (0.01 and 0.010000000000000002); a
    # user typing equal splits gets an error, tested elsewhere.
    assume(np.all(np.diff(np.concatenate([[near], interior, [far]])) > 0))
    splits = csm.split_distances(near, far, count, "MANUAL", manual=interior)
    assert splits[0] == near and splits[-1] == far
    assert np.all(np.diff(splits) > 0)
    np.testing.assert_array_equal(splits[1:-1], interior)


@pytest.mark.parametrize("count", [1, 2, 3, 4])
def test_hybrid_lambda_0_is_uniform_and_1_is_log(count):
    uniform = csm.split_distances(0.5, 300.0, count, "UNIFORM")
    log = csm.split_distances(0.5, 300.0, count, "LOG")
    np.testing.assert_array_equal(csm.split_distances(0.5, 300.0, count, "HYBRID", lam=0.0),
                                  uniform)
    np.testing.assert_array_equal(csm.split_distances(0.5, 300.0, count, "HYBRID", lam=1.0), log)
    assert count == 1 or not np.allclose(uniform, log)


def test_split_schemes_on_numbers():
    np.testing.assert_allclose(csm.split_distances(1.0, 10000.0, 4, "LOG"),
                               [1, 10, 100, 1000, 10000], rtol=1e-12)
    np.testing.assert_allclose(csm.split_distances(0.0, 90.0, 3, "UNIFORM"), [0, 30, 60, 90])
    # Course formula, N=2, lambda=0.5: z1 = 0.5*1*(100/1)^(1/2) + 0.5*(1 + 0.5*99) = 30.25
    np.testing.assert_allclose(csm.split_distances(1.0, 100.0, 2, "HYBRID", lam=0.5),
                               [1.0, 30.25, 100.0], rtol=1e-12)
    # N=3, lambda=0.75, n=0.1, f=100
    n, f, lam = 0.1, 100.0, 0.75
    expected = [lam * n * (f / n) ** (i / 3) + (1 - lam) * (n + i / 3 * (f - n)) for i in range(4)]
    np.testing.assert_allclose(csm.split_distances(n, f, 3, "hybrid", lam=lam), expected,
                               rtol=1e-12)


def test_manual_splits_from_fractions_of_shadow_distance():
    np.testing.assert_allclose(csm.manual_splits_from_fractions(200.0, (0.1, 0.3, 0.6), 3),
                               [20.0, 60.0])
    with pytest.raises(ValueError, match="4 cascades need 3"):
        csm.manual_splits_from_fractions(200.0, (0.1, 0.3), 4)


@pytest.mark.parametrize("kwargs, message", [
    (dict(count=0), "got 0"),
    (dict(count=5), "got 5"),
    (dict(count=2.5), "got 2.5"),
    (dict(count=True), "got True"),
    (dict(scheme="EXPONENTIAL"), "'EXPONENTIAL'"),
    (dict(scheme="HYBRID", lam=1.5), "got 1.5"),
    (dict(near=10.0, far=10.0), "far distance (10.0)"),
    (dict(near=50.0, far=10.0), "near distance (50.0)"),
    (dict(near=float("nan")), "nan"),
    (dict(near=0.0, scheme="LOG"), "got 0.0"),
    (dict(near=0.0, scheme="HYBRID", lam=0.3), "got 0.0"),
    (dict(scheme="MANUAL", manual=None), "got none"),
    (dict(scheme="MANUAL", manual=[5.0]), "got 1: [5.0]"),
    (dict(scheme="MANUAL", manual=[30.0, 20.0]), "manual split 2 (20.0)"),
    (dict(scheme="MANUAL", manual=[20.0, 20.0]), "manual split 2 (20.0)"),
    (dict(scheme="MANUAL", manual=[0.05, 20.0]), "manual split 1 (0.05)"),
    (dict(scheme="MANUAL", manual=[10.0, 100.0]), "manual split 2 (100.0)"),
    (dict(scheme="MANUAL", manual=[10.0, float("inf")]), "manual split 2 (inf)"),
])
def test_bad_split_inputs_raise_value_error_naming_the_value(kwargs, message):
    args = dict(near=0.1, far=100.0, count=3, scheme="UNIFORM")
    args.update(kwargs)
    with pytest.raises(ValueError, match=re.escape(message)):
        csm.split_distances(**args)


def test_manual_and_uniform_allow_zero_near_but_need_ordered_range():
    splits = csm.split_distances(0.0, 10.0, 2, "MANUAL", manual=[4.0])
    np.testing.assert_array_equal(splits, [0.0, 4.0, 10.0])


# ----------------------------------------------------------------------------------------
# projection and slice corners
# ----------------------------------------------------------------------------------------

def test_clip_from_view_matches_glu_perspective_without_shift():
    fov, aspect, n, f = math.radians(60), 1.5, 0.5, 80.0
    m = csm.CameraProjection(fov_y=fov, aspect=aspect, clip_start=n, clip_end=f).clip_from_view()
    cot = 1.0 / math.tan(fov / 2)
    expected = np.array([[cot / aspect, 0, 0, 0], [0, cot, 0, 0],
                         [0, 0, (f + n) / (n - f), 2 * f * n / (n - f)], [0, 0, -1, 0]])
    np.testing.assert_allclose(m, expected, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("seed", range(20))
def test_full_frustum_corners_project_to_the_clip_cube(seed):
    rng = np.random.default_rng(RNG_SEED + seed)
    projection = random_projection(rng)
    view = world_from_view(random_rotation(rng), rng.uniform(-100, 100, size=3))
    corners = csm.frustum_slice_corners(view, projection, projection.clip_start,
                                        projection.clip_end)
    clip_from_world = projection.clip_from_view() @ np.linalg.inv(view)
    homogeneous = np.c_[corners, np.ones(8)] @ clip_from_world.T
    ndc = homogeneous[:, :3] / homogeneous[:, 3:]
    expected = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                         [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
    np.testing.assert_allclose(ndc, expected, atol=1e-7)
    # The same corners when the projection is passed as the raw matrix (snapshot path).
    again = csm.frustum_slice_corners(view, projection.clip_from_view(), projection.clip_start,
                                      projection.clip_end)
    np.testing.assert_allclose(again, corners, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(10))
def test_projection_round_trips_through_its_matrix(seed):
    projection = random_projection(np.random.default_rng(RNG_SEED + 100 + seed))
    back = csm.CameraProjection.from_clip_from_view(projection.clip_from_view())
    assert back.kind == projection.kind
    for name in ("aspect", "shift_x", "shift_y", "clip_start", "clip_end",
                 "fov_y" if projection.is_perspective else "ortho_height"):
        assert getattr(back, name) == pytest.approx(getattr(projection, name), rel=1e-9, abs=1e-9)


def test_shift_is_measured_in_the_larger_image_dimension_like_blender():
    # Landscape: shift_x = 1 moves the window by one full image width.
    base = csm.CameraProjection(fov_y=0.8, aspect=2.0)
    shifted = csm.CameraProjection(fov_y=0.8, aspect=2.0, shift_x=1.0, shift_y=0.25)
    left, right, bottom, top = base.view_window()
    s_left, s_right, s_bottom, s_top = shifted.view_window()
    assert s_left == pytest.approx(right)
    # Vertical shift also uses the width (the larger side): 0.25 * width = half the height.
    assert s_bottom == pytest.approx(bottom + 0.25 * (right - left))
    assert s_top - s_bottom == pytest.approx(top - bottom)


def test_slice_corners_sit_at_the_requested_view_depths():
    corners = csm.view_slice_corners(DEFAULT_CAMERA, 2.0, 7.0)
    np.testing.assert_allclose(-corners[:4, 2], 2.0)
    np.testing.assert_allclose(-corners[4:, 2], 7.0)
    # Perspective: far corners are the near ones scaled by 7/2 (same frustum edges).
    np.testing.assert_allclose(corners[4:, :2], corners[:4, :2] * 3.5)


@pytest.mark.parametrize("call, message", [
    (lambda: csm.CameraProjection(kind="FISHEYE"), "'FISHEYE'"),
    (lambda: csm.CameraProjection(fov_y=4.0), "got 4.0"),
    (lambda: csm.CameraProjection(aspect=-1.0), "got -1.0"),
    (lambda: csm.CameraProjection(clip_start=0.0), "got 0.0"),
    (lambda: csm.CameraProjection(clip_start=5.0, clip_end=1.0), "clip_end (1.0)"),
    (lambda: csm.CameraProjection(kind="ORTHO", ortho_height=0.0), "got 0.0"),
    (lambda: csm.view_slice_corners(DEFAULT_CAMERA, 5.0, 2.0), "slice far depth (2.0)"),
    (lambda: csm.view_slice_corners(DEFAULT_CAMERA, 0.0, 2.0), "got 0.0"),
    (lambda: csm.frustum_slice_corners(np.eye(3), DEFAULT_CAMERA, 1, 2), "shape (3, 3)"),
    (lambda: csm.CameraProjection.from_clip_from_view(np.ones((4, 4))), "bottom row"),
])
def test_bad_camera_inputs_raise_value_error_naming_the_value(call, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        call()


# ----------------------------------------------------------------------------------------
# light view
# ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("direction", [(0, 0, -1), (0, 0, 1), (0, 1, 0), (0, -1, 0), (1, 0, 0),
                                       (1e-9, 0, -1), (0.3, 0.4, -0.866), (0, 1, 1e-9)])
def test_light_view_is_a_rotation_looking_along_the_light(direction):
    m = csm.light_view_matrix(direction)
    rotation = m[:3, :3]
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    np.testing.assert_array_equal(m[:3, 3], 0.0)
    unit = np.asarray(direction, float) / np.linalg.norm(direction)
    # The light looks down its -Z: the direction of travel is -row 2.
    np.testing.assert_allclose(-rotation[2], unit, atol=1e-12)


def test_light_view_does_not_flip_near_straight_down():
    straight = csm.light_view_matrix((0, 0, -1))
    for tilt in ((1e-7, 0, -1), (0, 1e-7, -1), (-1e-7, -1e-7, -1)):
        np.testing.assert_allclose(csm.light_view_matrix(tilt), straight, atol=1e-6)


def test_light_view_follows_the_up_hint():
    m = csm.light_view_matrix((0, 0, -1), up_hint=(1, 0, 0))
    np.testing.assert_allclose(m[1, :3], [1, 0, 0], atol=1e-12)
    # A hint parallel to the light is useless: it falls back instead of producing NaN.
    fallback = csm.light_view_matrix((0, 0, -1), up_hint=(0, 0, 5))
    assert np.all(np.isfinite(fallback))


def test_zero_light_direction_raises():
    with pytest.raises(ValueError, match=re.escape("[0.0, 0.0, 0.0]")):
        csm.light_view_matrix((0, 0, 0))


# ----------------------------------------------------------------------------------------
# bounding sphere
# ----------------------------------------------------------------------------------------

def test_bounding_sphere_of_a_box_is_half_its_diagonal():
    corners = np.array([[x, y, z] for x in (1, 3) for y in (-2, 2) for z in (10, 16)], float)
    centre, radius = csm.bounding_sphere(corners)
    np.testing.assert_allclose(centre, [2, 0, 13], atol=1e-12)
    assert radius == pytest.approx(math.sqrt(1 + 4 + 9))


@pytest.mark.parametrize("near, far", [(0.1, 5.0), (5.0, 20.0), (20.0, 200.0), (1.0, 1.5)])
def test_bounding_sphere_of_a_symmetric_slice_matches_the_closed_form(near, far):
    projection = csm.CameraProjection(fov_y=math.radians(50), aspect=16 / 9)
    centre, radius = csm.bounding_sphere(csm.view_slice_corners(projection, near, far))
    k2 = math.tan(projection.fov_y / 2) ** 2 * (1 + projection.aspect ** 2)
    if k2 >= (far - near) / (far + near):
        expected_depth, expected_radius = far, far * math.sqrt(k2)
    else:
        expected_depth = 0.5 * (far + near) * (1 + k2)
        expected_radius = 0.5 * math.sqrt((far - near) ** 2 + 2 * (far ** 2 + near ** 2) * k2
                                          + (far + near) ** 2 * k2 ** 2)
    np.testing.assert_allclose(centre, [0, 0, -expected_depth], atol=1e-9 * far)
    assert radius == pytest.approx(expected_radius, rel=1e-9)


def test_stabilized_cascades_get_the_exact_sphere_of_their_own_view_slice_every_time():
    # A camera-only redraw asks for the same view-space slices again: each cascade must get
    # the exact sphere of its own slice, whatever slices and cameras were asked for before.
    projection = csm.CameraProjection(fov_y=math.radians(50), aspect=16 / 9, clip_start=1.0,
                                      clip_end=40.0)
    turned = np.eye(4)
    turned[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    turned[:3, 3] = (5.0, -3.0, 2.0)
    for distance in (20.0, 21.0, 20.0):
        exact = csm.bounding_sphere(csm.view_slice_corners(projection, 1.0, distance))[1]
        for world_from_view in (np.eye(4), turned, np.eye(4)):
            fit = csm.compute_cascades(world_from_view, projection, (0.3, -0.2, -0.9), count=1,
                                       shadow_distance=distance).cascades[0]
            assert fit.sphere_radius == csm.round_up_radius(exact)
    assert csm.round_up_radius(csm.bounding_sphere(
        csm.view_slice_corners(projection, 1.0, 21.0))[1]) != csm.round_up_radius(
        csm.bounding_sphere(csm.view_slice_corners(projection, 1.0, 20.0))[1])


# ----------------------------------------------------------------------------------------
# fitting: corners inside, snapping, rotation invariance
# ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("stabilize", [True, False])
@pytest.mark.parametrize("seed", range(40))
def test_every_slice_corner_lies_inside_its_cascade_box(stabilize, seed):
    rng = np.random.default_rng(RNG_SEED + 1000 + seed)
    projection = random_projection(rng)
    view = world_from_view(random_rotation(rng), rng.uniform(-5000, 5000, size=3))
    result = csm.compute_cascades(view, projection, random_direction(rng),
                                  count=int(rng.integers(1, 5)),
                                  scheme=str(rng.choice(["UNIFORM", "LOG", "HYBRID"])),
                                  lam=rng.uniform(0, 1), stabilize=stabilize,
                                  occluder_margin=rng.uniform(0, 50),
                                  base_resolution=int(rng.choice([256, 1024, 2048])))
    for cascade in result.cascades:
        corners = csm.frustum_slice_corners(view, projection, cascade.split_near,
                                            cascade.split_far)
        clip = to_clip(cascade, corners)
        assert np.all(np.abs(clip) <= 1.0 + 1e-7), clip
        # and in light space within box_min..box_max
        light = np.c_[corners, np.ones(8)] @ cascade.light_from_world.T
        assert np.all(light[:, :3] >= cascade.box_min - 1e-7 * cascade.depth_range)
        assert np.all(light[:, :3] <= cascade.box_max + 1e-7 * cascade.depth_range)


def test_fit_cascade_accepts_world_corners_directly():
    corners = csm.frustum_slice_corners(default_view(), DEFAULT_CAMERA, 1.0, 12.0)
    rotation = csm.light_view_matrix(SUN_DIR)
    for stabilize in (True, False):
        fit = csm.fit_cascade(corners, rotation, 1024, stabilize=stabilize)
        assert np.all(np.abs(to_clip(fit, corners)) <= 1.0 + 1e-9)
        assert math.isnan(fit.split_near)


def test_tight_fit_uses_more_resolution_than_the_stable_fit():
    stable = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, stabilize=True)
    tight = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, stabilize=False)
    for a, b in zip(stable.cascades, tight.cascades):
        assert b.texel_size_world < a.texel_size_world


@pytest.mark.parametrize("seed", range(10))
def test_snapping_moves_the_box_by_whole_texels(seed):
    rng = np.random.default_rng(RNG_SEED + 2000 + seed)
    rotation = random_rotation(rng)
    start = rng.uniform(-1000, 1000, size=3)
    light_dir = random_direction(rng)
    first = csm.compute_cascades(world_from_view(rotation, start), DEFAULT_CAMERA, light_dir)
    for _ in range(5):
        moved = start + rng.normal(size=3) * rng.choice([1e-3, 0.05, 1.0])
        second = csm.compute_cascades(world_from_view(rotation, moved), DEFAULT_CAMERA, light_dir)
        for a, b in zip(first.cascades, second.cascades):
            assert a.texel_size_world == b.texel_size_world
            position_a, position_b = csm.texel_grid_position(a), csm.texel_grid_position(b)
            np.testing.assert_allclose(position_a, np.round(position_a), rtol=1e-6, atol=1e-6)
            offset = position_b - position_a
            np.testing.assert_allclose(offset, np.round(offset), rtol=1e-6, atol=1e-6)
            # What the user sees: a fixed world point keeps its place inside its texel.
            point = a.box_corners_world().mean(axis=0)
            phase_a = texel_coordinates(a, point) % 1.0
            phase_b = texel_coordinates(b, point) % 1.0
            difference = np.abs(phase_a - phase_b)
            assert np.all(np.minimum(difference, 1 - difference) < 1e-5)


def test_without_stabilization_the_box_slides_by_fractions_of_a_texel():
    # The counterpart of the snapping test: proves that test can fail.
    view_a, view_b = default_view((0, -20, 5)), default_view((0.0123, -20, 5))
    a = csm.compute_cascades(view_a, DEFAULT_CAMERA, SUN_DIR, stabilize=False).cascades[0]
    b = csm.compute_cascades(view_b, DEFAULT_CAMERA, SUN_DIR, stabilize=False).cascades[0]
    point = np.array([1.0, 5.0, 0.0])
    phase = (texel_coordinates(a, point) - texel_coordinates(b, point)) % 1.0
    assert np.any(np.minimum(phase, 1 - phase) > 1e-3)


@pytest.mark.parametrize("seed", range(10))
def test_stable_box_size_is_constant_while_the_camera_turns(seed):
    rng = np.random.default_rng(RNG_SEED + 3000 + seed)
    position = rng.uniform(-500, 500, size=3)
    projection = random_projection(rng)
    light_dir = random_direction(rng)
    sizes = set()
    for _ in range(8):
        view = world_from_view(random_rotation(rng), position)
        result = csm.compute_cascades(view, projection, light_dir, count=4)
        sizes.add(tuple(tuple((c.box_max[:2] - c.box_min[:2]).tolist() + [c.texel_size_world])
                        for c in result.cascades))
    assert len(sizes) == 1


def test_tight_box_size_changes_while_the_camera_turns():
    sizes = {tuple(csm.compute_cascades(
        world_from_view(rotation_matrix((0, 0, 1), angle) @ default_view()[:3, :3], (0, 0, 5)),
        DEFAULT_CAMERA, SUN_DIR, stabilize=False).cascades[0].box_max)
        for angle in (0.0, 0.3, 0.7)}
    assert len(sizes) == 3


def test_stable_texel_size_is_exactly_representable_and_covers_the_sphere():
    result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR)
    for cascade in result.cascades:
        texel = cascade.texel_size_world
        mantissa, _ = math.frexp(texel)
        assert (mantissa * 2 ** 9) == int(mantissa * 2 ** 9)      # at most 9 significant bits
        width = cascade.box_max[0] - cascade.box_min[0]
        assert width == pytest.approx(cascade.resolution * texel, rel=1e-12)
        assert width >= 2 * cascade.sphere_radius + texel


# ----------------------------------------------------------------------------------------
# occluder margin and scene bounds
# ----------------------------------------------------------------------------------------

def point_toward_light(cascade, distance):
    """A point in the middle of the cascade's slice, moved toward the light."""
    centre = cascade.sphere_center_world
    return centre - cascade.light_dir_world * (distance + cascade.sphere_radius)


@pytest.mark.parametrize("margin", [5.0, 40.0])
def test_occluder_margin_keeps_casters_between_light_and_slice_in_depth_range(margin):
    result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR,
                                  occluder_margin=margin)
    bare = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, occluder_margin=0.0)
    for cascade, bare_cascade in zip(result.cascades, bare.cascades):
        caster = point_toward_light(cascade, 0.99 * margin)
        assert np.all(np.abs(to_clip(cascade, caster)) <= 1.0)
        # Without the margin the same caster is in front of the near plane: clipped.
        assert to_clip(bare_cascade, caster)[0, 2] < -1.0
        # A margin does not move the box sideways.
        np.testing.assert_allclose(cascade.box_max[:2], bare_cascade.box_max[:2])


def test_scene_bounds_pull_the_near_plane_to_the_scene_corner_nearest_the_light():
    bounds = (np.array([-100.0, -100.0, 0.0]), np.array([100.0, 100.0, 60.0]))
    result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, (0, 0, -1), occluder_margin=0.0,
                                  scene_bounds=bounds)
    for cascade in result.cascades:
        # An off-screen caster at the top of the scene, right above the cascade.
        above = cascade.sphere_center_world.copy()
        above[2] = 60.0
        clip = to_clip(cascade, above)
        assert -1.0 - 1e-9 <= clip[0, 2] <= 1.0
        assert np.all(np.abs(clip[0, :2]) <= 1.0)


def test_default_occluder_margin_is_the_scene_diagonal():
    assert csm.default_occluder_margin(((0, 0, 0), (3, 4, 12))) == pytest.approx(13.0)
    assert csm.default_occluder_margin(None) == 0.0
    auto = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR,
                                scene_bounds=((-1, -1, -1), (1, 1, 1)))
    explicit = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR,
                                    occluder_margin=math.sqrt(12.0))
    np.testing.assert_allclose(auto.cascades[0].clip_from_world,
                               explicit.cascades[0].clip_from_world)


@pytest.mark.parametrize("call, message", [
    (lambda: csm.default_occluder_margin(((1, 0, 0), (0, 1, 1))), "[1.0, 0.0, 0.0]"),
    (lambda: csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, occluder_margin=-2),
     "got -2"),
    (lambda: csm.fit_cascade(np.zeros((8, 3)), np.diag([2.0, 1, 1, 1]), 512), "pure rotation"),
    (lambda: csm.fit_cascade(np.zeros((8, 3)), np.eye(4), 1), "got 1"),
    (lambda: csm.fit_cascade(np.zeros((4, 3)), np.eye(4), 512), "shape (4, 3)"),
])
def test_bad_fit_inputs_raise_value_error_naming_the_value(call, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        call()


# ----------------------------------------------------------------------------------------
# compute_cascades settings
# ----------------------------------------------------------------------------------------

def test_resolutions_halve_per_cascade_down_to_64_unless_equal():
    def resolutions(**kwargs):
        return [c.resolution for c in csm.compute_cascades(default_view(), DEFAULT_CAMERA,
                                                           SUN_DIR, **kwargs).cascades]
    assert resolutions() == [2048, 1024, 512]
    assert resolutions(count=4, base_resolution=128) == [128, 64, 64, 64]
    assert resolutions(count=4, base_resolution=1024, equal_resolution=True) == [1024] * 4
    assert csm.cascade_resolutions(2, 32) == [32, 32]


def test_shadow_distance_defaults_to_and_is_clamped_by_the_far_clip():
    for distance in (None, 0.0, 1e6):
        result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR,
                                      shadow_distance=distance)
        assert result.splits[-1] == DEFAULT_CAMERA.clip_end
    result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, shadow_distance=40.0)
    assert result.splits[0] == DEFAULT_CAMERA.clip_start and result.splits[-1] == 40.0
    assert result.cascades[-1].split_far == 40.0
    with pytest.raises(ValueError, match=re.escape("shadow distance (0.05)")):
        csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, shadow_distance=0.05)
    with pytest.raises(ValueError, match="got -1.0"):
        csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, shadow_distance=-1.0)


def test_orthographic_viewport_clipping_behind_the_eye_falls_back_to_uniform_and_says_so():
    # Blender's orthographic viewport clips from -clip_end/2.
    projection = csm.CameraProjection(kind="ORTHO", ortho_height=10.0, aspect=1.5,
                                      clip_start=-50.0, clip_end=100.0)
    result = csm.compute_cascades(default_view(), projection, SUN_DIR, scheme="HYBRID")
    assert result.scheme == "UNIFORM" and "uniform" in result.notes[0]
    np.testing.assert_allclose(result.splits, [-50, 0, 50, 100])
    for cascade in result.cascades:
        corners = csm.frustum_slice_corners(default_view(), projection, cascade.split_near,
                                            cascade.split_far)
        assert np.all(np.abs(to_clip(cascade, corners)) <= 1.0 + 1e-9)


def test_manual_scheme_through_compute_cascades():
    result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, scheme="MANUAL",
                                  manual=[10.0, 30.0], shadow_distance=80.0)
    np.testing.assert_array_equal(result.splits, [0.1, 10.0, 30.0, 80.0])


def test_box_corners_world_round_trip_to_the_clip_cube_corners():
    cascade = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR).cascades[1]
    clip = to_clip(cascade, cascade.box_corners_world())
    np.testing.assert_allclose(np.abs(clip), 1.0, atol=1e-9)
    np.testing.assert_allclose(clip[:4, 2], -1.0, atol=1e-9)     # near plane first
    assert cascade.window_depth_per_unit == pytest.approx(1.0 / cascade.far)


# ----------------------------------------------------------------------------------------
# culling
# ----------------------------------------------------------------------------------------

def culling_cascade():
    return csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, occluder_margin=10.0,
                                stabilize=False).cascades[0]


def test_boxes_far_outside_are_culled_and_overlapping_ones_kept():
    cascade = culling_cascade()
    centre = cascade.box_corners_world().mean(axis=0)
    half = 0.5 * np.ones(3)
    assert csm.aabb_in_cascade(centre - half, centre + half, cascade)
    # Sideways, far outside the box (perpendicular to the light).
    side = cascade.world_from_light[:3, 0] * 1000.0
    assert not csm.aabb_in_cascade(centre + side - half, centre + side + half, cascade)
    # A huge box containing the whole cascade is kept.
    assert csm.aabb_in_cascade(centre - 1e4, centre + 1e4, cascade)
    # A box straddling a side face is kept.
    edge = cascade.world_from_light[:3, 0] * cascade.box_max[0]
    assert csm.aabb_in_cascade(centre + edge - half, centre + edge + half, cascade)


def test_boxes_between_the_light_and_the_cascade_are_kept_and_behind_it_culled():
    cascade = culling_cascade()
    centre = cascade.box_corners_world().mean(axis=0)
    half = 0.5 * np.ones(3)
    toward_light = centre - cascade.light_dir_world * 5000.0     # way past the near plane
    assert csm.aabb_in_cascade(toward_light - half, toward_light + half, cascade)
    behind = centre + cascade.light_dir_world * (cascade.depth_range + 10.0)
    assert not csm.aabb_in_cascade(behind - half, behind + half, cascade)


def test_vectorised_culling_matches_the_8_corner_test():
    rng = np.random.default_rng(RNG_SEED + 4000)
    cascade = culling_cascade()
    centre = cascade.box_corners_world().mean(axis=0)
    low = centre + rng.uniform(-150, 150, size=(2000, 3))
    high = low + rng.uniform(0, 20, size=(2000, 3))
    mask = csm.aabbs_in_cascade(low, high, cascade)
    expected = []
    for lo, hi in zip(low, high):
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        light = np.c_[corners, np.ones(8)] @ cascade.light_from_world.T
        mn, mx = light[:, :3].min(axis=0), light[:, :3].max(axis=0)
        expected.append(bool(np.all(mx[:2] >= cascade.box_min[:2])
                             and np.all(mn[:2] <= cascade.box_max[:2])
                             and mx[2] >= cascade.box_min[2]))
    np.testing.assert_array_equal(mask, expected)
    assert 0 < mask.sum() < len(mask)      # the sample has both outcomes
    assert csm.aabb_in_cascade(low[0], high[0], cascade) == mask[0]


def test_culling_with_boxes_turned_for_another_cascade_of_the_same_sun():
    """The boxes turned into one cascade's light frame (``boxes_in_light_frame``) cull the
    same against every cascade with that rotation: what the pipeline keeps between them."""
    rng = np.random.default_rng(RNG_SEED + 4001)
    result = csm.compute_cascades(default_view(), DEFAULT_CAMERA, SUN_DIR, count=3)
    low = result.cascades[0].box_corners_world().mean(axis=0) + \
        rng.uniform(-150, 150, size=(500, 3))
    high = low + rng.uniform(0, 8, size=(500, 3))
    rotated = csm.boxes_in_light_frame(low, high, result.cascades[0].light_from_world)
    for cascade in result.cascades:
        np.testing.assert_array_equal(
            csm.aabbs_in_cascade(low, high, cascade, checked=True, rotated=rotated),
            csm.aabbs_in_cascade(low, high, cascade))


def test_bad_culling_input_names_the_box():
    cascade = culling_cascade()
    low = np.zeros((3, 3))
    high = np.ones((3, 3))
    high[2] = -1.0
    with pytest.raises(ValueError, match=re.escape("AABB 2")):
        csm.aabbs_in_cascade(low, high, cascade)


# ----------------------------------------------------------------------------------------
# spot light
# ----------------------------------------------------------------------------------------

def spot_pose():
    pose = world_from_view(rotation_matrix((1, 1, 0), 2.3), (3.0, -4.0, 6.0))
    pose[:3, :3] *= 2.5            # object scale must not matter
    return pose


def test_spot_matrix_maps_the_aim_direction_to_the_centre():
    pose = spot_pose()
    light_from_world, clip_from_light = csm.spot_light_matrices(pose, math.radians(60), 0.1, 50)
    aim = -pose[:3, 2] / np.linalg.norm(pose[:3, 2])
    point = pose[:3, 3] + aim * 10.0
    clip = clip_from_light @ light_from_world @ np.r_[point, 1.0]
    np.testing.assert_allclose(clip[:2] / clip[3], 0.0, atol=1e-12)
    assert -1.0 < clip[2] / clip[3] < 1.0


def test_spot_cone_edge_maps_to_the_map_edge():
    pose = spot_pose()
    angle = math.radians(70)
    light_from_world, clip_from_light = csm.spot_light_matrices(pose, angle, 0.1, 50)
    light_point = np.array([0.0, math.tan(angle / 2) * 8.0, -8.0, 1.0])   # on the cone, +Y
    point = np.linalg.inv(light_from_world) @ light_point
    clip = clip_from_light @ light_from_world @ point
    np.testing.assert_allclose(clip[:2] / clip[3], [0.0, 1.0], atol=1e-12)
    rotation = light_from_world[:3, :3]
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert csm.spot_texel_size(angle, 1024, 8.0) == pytest.approx(
        2 * math.tan(angle / 2) * 8.0 / 1024)


@pytest.mark.parametrize("args, message", [
    ((math.pi, 0.1, 10), "got 3.14159"),
    ((0.0, 0.1, 10), "got 0.0"),
    ((1.0, 0.0, 10), "got 0.0"),
    ((1.0, 5.0, 2.0), "clip end (2.0)"),
])
def test_bad_spot_inputs_raise_value_error_naming_the_value(args, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        csm.spot_light_matrices(np.eye(4), *args)


# blend bands
# ----------------------------------------------------------------------------------------

SPLITS = np.array([0.1, 10.0, 30.0, 100.0])


def test_blend_band_is_capped_at_half_the_nearer_cascade():
    widths = csm.blend_band_widths(SPLITS, 50.0)
    np.testing.assert_allclose(widths, [4.95, 10.0, 0.0])
    with pytest.raises(ValueError, match="got -1.0"):
        csm.blend_band_widths(SPLITS, -1.0)


def test_no_blend_band_and_none_after_the_last_cascade():
    np.testing.assert_array_equal(csm.blend_band_widths(SPLITS, 0.0), 0.0)
    np.testing.assert_allclose(csm.blend_band_widths(SPLITS, 2.0), [2.0, 2.0, 0.0])


def test_modules_import_neither_bpy_nor_gpu():
    for path in Path(csm.__file__).parent.glob("*.py"):
        source = path.read_text()
        assert not re.search(r"^\s*(import|from)\s+(bpy|gpu)\b", source, re.MULTILINE), path
