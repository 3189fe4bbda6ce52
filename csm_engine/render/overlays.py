"""Overlays drawn over the lit image: the frozen cascades' light-space boxes and the
viewport's cascade-colour legend (or the Shadow error view's shares).

Owns ``draw_frozen_cascades`` (coloured lines, one colour per cascade, while Freeze
Cascades holds them), ``draw_overlays`` (the same into a given framebuffer, after
anti-aliasing, so 1-pixel lines stay crisp), and the legend's rows (``cascade_legend``:
colour and depth range of each cascade, while the Cascades view is on; ``legend_rows``
adds the Shadow error view's false and missed shares), its layout
in pixels (``legend_layout``) and its panel and swatches (``draw_legend_swatches``). The
legend's text is Blender's (``blf``), so the engine writes it; final renders get no
legend, so their Combined pass holds only the scene.
"""

import math
from typing import NamedTuple

import numpy as np

from ..core.shadow_plan import CASCADE_LINE_COLORS
from . import shaders
from .draw_lists import column_major

# The 12 edges of a box whose corners are numbered x + 2 y + 4 z (0/1 each).
_BOX_EDGES = ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7),
              (0, 4), (1, 5), (2, 6), (3, 7))


def draw_frozen_cascades(snap, plan):
    """Draw each frozen cascade's light-space box as coloured lines into the bound
    framebuffer, seen by ``snap``'s camera."""
    import gpu
    lines, colors = [], []
    for index, tile in enumerate(plan.tiles[:plan.cascade_count]):
        world_from_clip = np.linalg.inv(tile.clip_from_world)
        corners = np.array([[x, y, z, 1.0] for z in (-1, 1) for y in (-1, 1)
                            for x in (-1, 1)]) @ world_from_clip.T
        corners = corners[:, :3] / corners[:, 3:]
        for a, b in _BOX_EDGES:
            lines += [corners[a], corners[b]]
            colors += [CASCADE_LINE_COLORS[index]] * 2
    if not lines:
        return
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="color", comp_type='F32', len=4, fetch_mode='FLOAT')
    vbo = gpu.types.GPUVertBuf(fmt, len(lines))
    vbo.attr_fill("pos", np.array(lines, dtype=np.float32))
    vbo.attr_fill("color", np.array(colors, dtype=np.float32))
    batch = gpu.types.GPUBatch(type='LINES', buf=vbo)
    shader = shaders.LIBRARY.get("lines")
    shader.bind()
    shader.uniform_float("clip_from_world", column_major(snap.camera.clip_from_world))
    batch.draw(shader)


def draw_overlays(snap, plan, target_fb, width, height):
    """The overlays of ``plan`` into ``target_fb`` (nothing unless cascades are frozen)."""
    import gpu
    if plan.frozen_camera is None:
        return
    with target_fb.bind():
        gpu.state.viewport_set(0, 0, width, height)
        draw_frozen_cascades(snap, plan)


# The colours debug_views.glsl's ``cascade_color`` tints cascades 1..4 with (a test reads
# them from the shader): the legend's swatches show the brightest tint of each.
CASCADE_VIEW_COLORS = ((1.0, 0.15, 0.15), (0.15, 1.0, 0.15), (0.2, 0.3, 1.0),
                       (1.0, 1.0, 0.15))

# The legend's sizes in pixels at UI scale 1.
LEGEND_PADDING = 6
LEGEND_SWATCH = 12
LEGEND_GAP = 6
LEGEND_ROW = 16
# Behind the rows, so white text stays readable over a bright sky or a yellow cascade.
LEGEND_PANEL_COLOR = (0.0, 0.0, 0.0, 0.5)


class LegendRow(NamedTuple):
    """One cascade in the legend: its number (1 = nearest), the colour its pixels are
    tinted with (RGB) and its label, e.g. "1  0.1-12 m" (its view-depth range)."""
    number: int
    color: tuple
    label: str


def metres(value):
    """A depth for a label: whole metres from 10 m, else two significant digits
    ("0.1", "2.4", "12", "150")."""
    if value >= 10.0:
        return f"{value:.0f}"
    if value <= 0.0:
        return "0"
    decimals = max(1, 1 - math.floor(math.log10(value)))
    return f"{value:.{decimals}f}".rstrip("0").rstrip(".")


def cascade_legend(snap, plan):
    """The legend's rows for a frame drawn with ``plan``: one per cascade in use, nearest
    first, while Debug View is Cascades; none otherwise (also none without a
    shadow-casting sun, whose view shows no cascades)."""
    if plan is None or snap.settings.debug_view != "CASCADES":
        return []
    splits = plan.splits
    rows = []
    for index in range(min(plan.cascade_count, len(CASCADE_VIEW_COLORS))):
        near, far = float(splits[index]), float(splits[index + 1])
        rows.append(LegendRow(index + 1, CASCADE_VIEW_COLORS[index],
                              f"{index + 1}  {metres(near)}-{metres(far)} m"))
    return rows


# The Shadow error view's colours (debug_views.glsl's shadow_error_color).
SHADOW_ERROR_COLORS = ((1.0, 0.0, 0.0), (0.0, 1.0, 1.0))


def legend_rows(snap, plan, shadow_error=None):
    """The legend's rows for this frame: the cascades' in the Cascades view, the shares of
    false and missed shadow in the Shadow error view (``shadow_error``: the pipeline's
    ``ShadowError`` of the frame), none otherwise."""
    if snap.settings.debug_view == "SHADOW_ERROR" and shadow_error is not None:
        return [LegendRow(1, SHADOW_ERROR_COLORS[0],
                          f"false shadow {100 * shadow_error.false_shadow:.2f} %"),
                LegendRow(2, SHADOW_ERROR_COLORS[1],
                          f"missed shadow {100 * shadow_error.missed_shadow:.2f} %")]
    return cascade_legend(snap, plan)


class LegendLayout(NamedTuple):
    """Where the legend goes, in whole pixels from the viewport's bottom-left corner:
    the panel (x0, y0, x1, y1), each row's swatch rectangle and the position of its
    label's baseline (x, y), rows top to bottom as in ``cascade_legend``."""
    rows: list
    panel: tuple
    swatches: list
    labels: list


def legend_layout(rows, text_width, left, bottom, scale=1.0):
    """Lay ``rows`` out in a panel whose bottom-left corner is (``left``, ``bottom``);
    ``text_width``: the widest label in pixels; ``scale``: Blender's UI scale."""
    def px(value):
        return int(round(value * scale))
    pad, swatch, gap, row = px(LEGEND_PADDING), px(LEGEND_SWATCH), px(LEGEND_GAP), \
        px(LEGEND_ROW)
    left, bottom = int(left), int(bottom)
    width = pad + swatch + gap + int(math.ceil(text_width)) + pad
    height = 2 * pad + len(rows) * row
    swatches, labels = [], []
    for index in range(len(rows)):
        y = bottom + pad + (len(rows) - 1 - index) * row
        sy = y + (row - swatch) // 2
        swatches.append((left + pad, sy, left + pad + swatch, sy + swatch))
        # The label's baseline, so capitals sit centred on the swatch.
        labels.append((left + pad + swatch + gap, sy + px(2)))
    return LegendLayout(rows, (left, bottom, left + width, bottom + height), swatches,
                        labels)


# Where debug_views.glsl's shadow_map_uv puts the Inset shadow map: 8 pixels from the
# bottom-left corner, 0.35 of the viewport's shorter side wide.
INSET_ORIGIN = 8
INSET_SHARE = 0.35


def legend_corner(snap, width, height, left=0, bottom=0, scale=1.0):
    """The legend panel's bottom-left corner: a margin inside the part of the viewport
    (``left``, ``bottom``) that Blender's toolbar and other regions leave visible, and
    above the Inset shadow map when that is shown."""
    margin = int(round(LEGEND_PADDING * 2 * scale))
    if snap.settings.debug_inset:
        bottom = max(bottom, INSET_ORIGIN + int(math.ceil(INSET_SHARE * min(width, height))))
    return int(left) + margin, int(bottom) + margin


def _rectangles(rectangles, colors):
    """Two triangles per (x0, y0, x1, y1), one RGBA colour each: positions and colours."""
    positions, vertex_colors = [], []
    for (x0, y0, x1, y1), color in zip(rectangles, colors):
        for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y0), (x1, y1), (x0, y1)):
            positions.append((x, y, 0.0))
            vertex_colors.append(color)
    return positions, vertex_colors


def pixel_space(width, height):
    """The clip-from-pixel matrix of a ``width`` x ``height`` viewport (bottom-left origin)."""
    return np.array([[2.0 / width, 0, 0, -1], [0, 2.0 / height, 0, -1], [0, 0, -1, 0],
                     [0, 0, 0, 1]])


def draw_legend_swatches(layout, width, height):
    """The legend's translucent panel, then its swatches in exactly the cascade colours,
    into the bound framebuffer (the labels are written over it by the caller)."""
    import gpu
    if not layout.rows:
        return
    shader = shaders.LIBRARY.get("lines")
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="color", comp_type='F32', len=4, fetch_mode='FLOAT')
    previous_blend = gpu.state.blend_get() if hasattr(gpu.state, "blend_get") else 'NONE'
    gpu.state.viewport_set(0, 0, width, height)
    gpu.state.depth_test_set('NONE')
    shader.bind()
    shader.uniform_float("clip_from_world", column_major(pixel_space(width, height)))
    parts = (('ALPHA', [layout.panel], [LEGEND_PANEL_COLOR]),
             ('NONE', layout.swatches, [tuple(row.color) + (1.0,) for row in layout.rows]))
    for blend, rectangles, colors in parts:
        positions, vertex_colors = _rectangles(rectangles, colors)
        vbo = gpu.types.GPUVertBuf(fmt, len(positions))
        vbo.attr_fill("pos", np.array(positions, dtype=np.float32))
        vbo.attr_fill("color", np.array(vertex_colors, dtype=np.float32))
        gpu.state.blend_set(blend)
        gpu.types.GPUBatch(type='TRIS', buf=vbo).draw(shader)
    gpu.state.blend_set(previous_blend)
