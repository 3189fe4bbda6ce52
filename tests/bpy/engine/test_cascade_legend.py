"""The cascade-colour legend: while Debug View is Cascades the viewport shows one
swatch per cascade in the exact colour the lighting shader tints it with, labelled with
its number and depth range in metres, in the bottom-left corner Blender's regions leave
visible; the lit view and final renders show none.

Frames are drawn as ``view_draw`` draws them: ``Pipeline.draw_viewport`` (through FXAA)
into an offscreen target, then ``engine.draw_cascade_legend``.
"""
import re
from pathlib import Path
from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from csm_engine.blender import engine, mesh_cache, snapshot
from csm_engine.render import overlays, pipeline
from tests.bpy.bpy_helpers import cube_on_plane, render_result, render_scene

WIDTH, HEIGHT = 320, 240
SHADERS = Path(__file__).resolve().parents[3] / "shaders"


@pytest.fixture
def cascade_scene(empty_scene):
    cube_on_plane(empty_scene)
    empty_scene.csm.cascade_count = 3
    empty_scene.csm.debug_view = 'CASCADES'
    render_scene(empty_scene, 32, 32)          # a GPU context exists from here on
    return empty_scene


def _frame(scene, legend=True, corner=(0, 0), scale=1.0):
    """One viewport frame as view_draw draws it; returns (RGBA bottom row first, snapshot,
    plan)."""
    import gpu
    depsgraph = bpy.context.evaluated_depsgraph_get()
    camera = snapshot.camera_from_scene(scene, depsgraph, WIDTH, HEIGHT)
    snap = snapshot.take(depsgraph, camera, is_viewport=True)
    cache = mesh_cache.MeshCache()
    cache.sync(snap.mesh_sources)
    snap.mesh_sources = {}
    offscreen = gpu.types.GPUOffScreen(WIDTH, HEIGHT, format='RGBA32F')
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0, 0, 0, 1))
            plan = pipeline.Pipeline().draw_viewport(snap, cache, WIDTH, HEIGHT, fxaa=True)
            if legend:
                engine.draw_cascade_legend(snap, plan, WIDTH, HEIGHT, *corner, scale)
            buffer = gpu.types.Buffer('FLOAT', WIDTH * HEIGHT * 4)
            fb.read_color(0, 0, WIDTH, HEIGHT, 4, 0, 'FLOAT', data=buffer)
    finally:
        offscreen.free()
        gpu.state.blend_set('NONE')
        cache.clear()
    return np.frombuffer(buffer, np.float32).reshape(HEIGHT, WIDTH, 4).copy(), snap, plan


def _layout(snap, plan, corner=(0, 0), scale=1.0):
    """The layout ``draw_cascade_legend`` used (its text width measured the same way)."""
    import blf
    from csm_engine.blender import compat
    rows = overlays.cascade_legend(snap, plan)
    compat.blf_size(0, max(int(round(11 * scale)), 6))
    width = max(blf.dimensions(0, row.label)[0] for row in rows)
    return overlays.legend_layout(rows, width, *overlays.legend_corner(
        snap, WIDTH, HEIGHT, *corner, scale), scale=scale)


def test_the_swatch_colours_are_those_the_shader_tints_cascades_with():
    source = (SHADERS / "debug_views.glsl").read_text(encoding="utf-8")
    body = source[source.index("vec3 cascade_color("):]
    body = body[:body.index("}")]
    found = [tuple(float(v) for v in c.split(","))
             for c in re.findall(r"vec3\(([\d.,\s]+)\)", body.split("=", 1)[1])]
    assert tuple(found[:4]) == overlays.CASCADE_VIEW_COLORS


def test_labels_give_each_cascade_its_number_and_depth_range_in_metres():
    plan = SimpleNamespace(cascade_count=3, splits=np.array([0.1, 12.3, 40.0, 150.0]))
    cascades = SimpleNamespace(settings=SimpleNamespace(debug_view="CASCADES"))
    lit = SimpleNamespace(settings=SimpleNamespace(debug_view="NONE"))
    assert [row.label for row in overlays.cascade_legend(cascades, plan)] == \
        ["1  0.1-12 m", "2  12-40 m", "3  40-150 m"]
    assert overlays.cascade_legend(lit, plan) == []
    assert overlays.cascade_legend(cascades, SimpleNamespace(
        cascade_count=0, splits=np.array([0.1, 100.0]))) == []
    assert [overlays.metres(v) for v in (0.05, 0.1, 2.35, 5.0, 9.96, 12.3, 1000.0)] == \
        ["0.05", "0.1", "2.4", "5", "10", "12", "1000"]


def test_the_legend_stays_clear_of_the_toolbar_and_the_inset():
    window = SimpleNamespace(type='WINDOW', x=100, y=50, width=800, height=600)
    toolbar = SimpleNamespace(type='TOOLS', x=100, y=50, width=45, height=560)
    header = SimpleNamespace(type='HEADER', x=100, y=650, width=800, height=26)
    sidebar = SimpleNamespace(type='UI', x=900, y=50, width=200, height=600)   # no overlap
    area = SimpleNamespace(regions=[header, toolbar, window, sidebar])
    assert engine.visible_corner(area, window) == (45, 0)
    assert engine.visible_corner(None, window) == (0, 0)
    snap = SimpleNamespace(settings=SimpleNamespace(debug_inset=True))
    _, bottom = overlays.legend_corner(snap, 320, 240)
    assert bottom > 8 + 0.35 * 240


def test_looking_through_the_camera_the_legend_sits_inside_its_frame(cascade_scene):
    """Blender dims the viewport outside the camera frame: the legend goes inside it."""
    from mathutils import Matrix
    camera = cascade_scene.camera
    cascade_scene.render.resolution_x, cascade_scene.render.resolution_y = 800, 600
    depsgraph = bpy.context.evaluated_depsgraph_get()
    region = SimpleNamespace(width=800, height=600)
    projection = camera.calc_matrix_camera(depsgraph, x=800, y=600)
    half = Matrix.Diagonal((0.5, 0.5, 1.0, 1.0))   # the frame fills the middle half
    view = SimpleNamespace(view_perspective='CAMERA',
                           perspective_matrix=half @ projection @ camera.matrix_world.inverted())
    left, bottom = engine.camera_frame_corner(cascade_scene, region, view)
    assert abs(left - 200) <= 1 and abs(bottom - 150) <= 1, (left, bottom)
    view.view_perspective = 'PERSP'
    assert engine.camera_frame_corner(cascade_scene, region, view) == (0, 0)


def test_the_cascade_view_shows_a_swatch_per_cascade_in_its_colour(cascade_scene):
    pixels, snap, plan = _frame(cascade_scene, corner=(45, 0))
    layout = _layout(snap, plan, corner=(45, 0))
    assert plan.cascade_count == 3 and len(layout.swatches) == 3
    x0, y0, x1, y1 = layout.panel
    assert x0 >= 45 and y0 >= 0 and x1 < WIDTH // 2 and y1 < HEIGHT // 2, layout.panel
    for (sx0, sy0, sx1, sy1), color in zip(layout.swatches, overlays.CASCADE_VIEW_COLORS):
        inside = pixels[sy0 + 1:sy1 - 1, sx0 + 1:sx1 - 1, :3]
        assert inside.size and np.allclose(inside, color, atol=1e-6), (color, inside[0, 0])
    # Cascade 1 (nearest) is the top row.
    assert layout.swatches[0][1] > layout.swatches[-1][1]
    # The labels are written right of the swatches in light grey, inside the panel.
    text_area = pixels[y0:y1, layout.labels[0][0]:x1, :3]
    assert (text_area.min(axis=-1) > 0.6).sum() > 40, "the labels are drawn"


def test_the_lit_view_and_final_renders_have_no_legend(cascade_scene):
    cascade_scene.csm.debug_view = 'NONE'
    with_call, _, _ = _frame(cascade_scene)
    without, _, _ = _frame(cascade_scene, legend=False)
    assert np.array_equal(with_call, without)
    # A final render of the cascade view: its Combined pass is the scene's pixels only.
    cascade_scene.csm.debug_view = 'CASCADES'
    combined = render_result(cascade_scene, WIDTH, HEIGHT).images["combined"][::-1]
    viewport, snap, plan = _frame(cascade_scene, legend=False)
    x0, y0, x1, y1 = _layout(snap, plan).panel
    panel = combined[y0:y1, x0:x1, :3]
    assert not np.any(np.all(np.abs(panel - overlays.CASCADE_VIEW_COLORS[0]) < 1e-6, axis=-1))
