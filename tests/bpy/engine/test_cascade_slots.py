"""A final render's sun cascades have two atlas slots (``shadow_plan.CASCADE_SLOTS``): a
box that comes back after a render with another box finds its shadow map in its other
slot and draws nothing, and a map read from either slot gives the same pixels, so a
frame's pixels do not depend on the renders before it."""
import numpy as np

from csm_engine.core import shadow_plan
from tests.bpy.bpy_helpers import cube_on_plane, render_result

W, H = 96, 64


def _cascade_origins(result):
    return [tuple(tile.origin) for tile in result.plan.tiles if tile.cascade is not None]


def _back_and_forth(scene):
    """Renders at the camera's pose A, at pose B (turned 3 degrees), at A again."""
    camera = scene.camera
    results = [render_result(scene, W, H)]
    camera.rotation_euler.z += np.radians(3.0)
    results.append(render_result(scene, W, H))
    camera.rotation_euler.z -= np.radians(3.0)
    results.append(render_result(scene, W, H))
    return results


def test_a_box_that_comes_back_finds_its_map_and_the_same_pixels(empty_scene):
    cube_on_plane(empty_scene)
    first, moved, back = _back_and_forth(empty_scene)
    assert moved.passes.shadow_tiles_drawn > 0, "the turn changes some cascade's box"
    assert back.passes.shadow_tiles_drawn == 0
    # A redrawn cascade went to its other slot, and coming back reads the first one.
    assert _cascade_origins(moved) != _cascade_origins(first)
    assert _cascade_origins(back) == _cascade_origins(first)
    assert np.array_equal(back.images["combined"], first.images["combined"])
    # Pose C (turned the other way) takes B's slot, B then A's, and A comes back into
    # the other slot than at first: the same pixels.
    camera = empty_scene.camera
    for turn in (-3.0, 6.0, -3.0):
        camera.rotation_euler.z += np.radians(turn)
        again = render_result(empty_scene, W, H)
    assert again.passes.shadow_tiles_drawn > 0
    assert _cascade_origins(again) != _cascade_origins(first)
    assert np.array_equal(again.images["combined"], first.images["combined"])

def test_with_one_slot_a_box_that_comes_back_is_drawn_again(empty_scene, monkeypatch):
    monkeypatch.setattr(shadow_plan, "CASCADE_SLOTS", 1)
    cube_on_plane(empty_scene)
    first, moved, back = _back_and_forth(empty_scene)
    assert back.passes.shadow_tiles_drawn == moved.passes.shadow_tiles_drawn > 0
    assert np.array_equal(back.images["combined"], first.images["combined"])
