"""The visible depth reduction (``render/visible_depth.py``, ``depth_range_frag.glsl``)
against the view depth it reduces, block by block on the CPU: each 16x16 block's nearest
and farthest view depth, background (0) left out, whatever the view's size."""
import gpu
import numpy as np
import pytest

from csm_engine.render import visible_depth
from csm_engine.render.resources import Targets
from tests.bpy.bpy_helpers import cube_on_plane, render_scene

NOTHING = 3.0e38
BLOCK = visible_depth.VisibleDepth.DEPTH_BLOCK_PIXELS


def _reduced(depth):
    """(rows, cols, 2) nearest and farthest per block of ``depth`` (H, W), on the GPU."""
    height, width = depth.shape
    source = gpu.types.GPUTexture((width, height), format='R32F', data=gpu.types.Buffer(
        'FLOAT', width * height, depth.ravel().tolist()))
    target, fb = visible_depth.reduce_min_max(Targets(), "test_depth_range", source,
                                              (width, height), 2, source_is_view_depth=True)
    buffer = gpu.types.Buffer('FLOAT', target.width * target.height * 4)
    with fb.bind():
        fb.read_color(0, 0, target.width, target.height, 4, 0, 'FLOAT', data=buffer)
    return np.array(buffer.to_list(), dtype=np.float32).reshape(
        target.height, target.width, 4)[..., :2]


def _expected(depth):
    rows, cols = -(-depth.shape[0] // BLOCK), -(-depth.shape[1] // BLOCK)
    pairs = np.zeros((rows, cols, 2), dtype=np.float32)
    for row in range(rows):
        for col in range(cols):
            block = depth[row * BLOCK:(row + 1) * BLOCK, col * BLOCK:(col + 1) * BLOCK]
            shown = block[block > 0.0]
            pairs[row, col] = (shown.min(), shown.max()) if len(shown) else (NOTHING, 0.0)
    return pairs


def _view_depth(height, width):
    """Random depths over 0.5 .. 200 with a third of the pixels background, one block all
    background and one pixel nearer than the rest."""
    rng = np.random.default_rng(height * 1000 + width)
    depth = rng.uniform(0.5, 200.0, (height, width)).astype(np.float32)
    depth[rng.random((height, width)) < 0.3] = 0.0
    depth[:BLOCK, BLOCK:2 * BLOCK] = 0.0
    depth[height - 1, width - 1] = 0.25
    return depth


@pytest.fixture
def gpu_context(empty_scene):
    cube_on_plane(empty_scene)
    render_scene(empty_scene, 16, 16)      # a GPU context exists from here on


@pytest.mark.parametrize("height, width", [(48, 64), (62, 98), (35, 83)])
def test_each_block_holds_the_nearest_and_farthest_depth_it_shows(gpu_context, height,
                                                                  width):
    depth = _view_depth(height, width)
    assert np.array_equal(_reduced(depth), _expected(depth))


def test_a_last_block_one_pixel_wide_may_only_widen_its_range(gpu_context):
    """A view one pixel wider (and taller) than whole 4x4 steps: the last blocks' range may
    take in their neighbours' last pixels, never lose their own; the others are exact."""
    depth = _view_depth(61, 97)
    got, expected = _reduced(depth), _expected(depth)
    assert np.array_equal(got[:-1, :-1], expected[:-1, :-1])
    assert np.all(got[..., 0] <= expected[..., 0]) and np.all(got[..., 1] >= expected[..., 1])
    assert got[-1, -1, 0] == pytest.approx(0.25)
