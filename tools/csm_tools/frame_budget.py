"""What a camera-animation frame at 20x EEVEE's speed would leave for shading, and the
least the passes it cannot skip cost on this machine.

Owns ``minimal_pass_seconds`` (the least a full-screen pass costs at a resolution: read the
two packed G-buffer targets at each pixel, write one RGBA32F target), ``triangle_floor``
(the least a pass drawing N small triangles costs: depth only as a shadow map, then with
the G-buffer's two colour targets, then with its ten interpolated values), the
benchmark's budget table (``budget_rows``, ``budget_markdown``): per scene, EEVEE's
frame of the same animation divided by 20, less what CSM's frame spends before and around
its shading passes (the shadow maps and the G-buffer, which cost per triangle; reading the
scene and meshes, planning, the visible-depth reduction, read-back and Blender's hand-off),
against what the AO, lighting and FXAA passes spend now, and ``./dev frame-floor``.

    ./dev frame-floor [--resolution 1280x720] [--triangles 252000]
"""

import argparse
import statistics
import sys
import time

TARGET_RATIO = 20.0
GEOMETRY_STEPS = ("shadow", "gbuffer")
FIXED_STEPS = ("scene_read", "mesh_upload", "python_setup", "depth_range", "readback",
               "blender")
SHADING_STEPS = ("ao", "lighting", "fxaa")

_VERTEX = "void main() { gl_Position = vec4(pos, 0.0, 1.0); }"
_FRAGMENT = """
void main()
{
  ivec2 px = ivec2(gl_FragCoord.xy);
  out_color = texelFetch(surface, px, 0) + texelFetch(view_depth, px, 0).xyxy;
}
"""


def minimal_pass_seconds(width, height, repeat=7):
    """Median seconds of a full-screen pass that reads two float textures of
    ``width`` x ``height`` (RGBA32F and RG32F, as the packed G-buffer) at each pixel and
    writes one RGBA32F target, each draw waited for with a 1-pixel read. No shading: the
    least any of CSM's full-screen passes can cost here."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, 'VEC2', "pos")
    info.sampler(0, 'FLOAT_2D', "surface")
    info.sampler(1, 'FLOAT_2D', "view_depth")
    info.fragment_out(0, 'VEC4', "out_color")
    info.vertex_source(_VERTEX)
    info.fragment_source(_FRAGMENT)
    shader = gpu.shader.create_from_info(info)
    surface = gpu.types.GPUTexture((width, height), format='RGBA32F')
    view_depth = gpu.types.GPUTexture((width, height), format='RG32F')
    target = gpu.types.GPUTexture((width, height), format='RGBA32F')
    fb = gpu.types.GPUFrameBuffer(color_slots=(target,))
    batch = batch_for_shader(shader, 'TRIS', {"pos": ((-1, -1), (3, -1), (-1, 3))})
    return _median_draw_seconds(fb, shader, batch, width, height, repeat,
                                samplers={"surface": surface, "view_depth": view_depth})


def _median_draw_seconds(fb, shader, batch, width, height, repeat, samplers=(),
                         depth_test=False):
    """Median seconds of ``repeat`` draws of ``batch`` into ``fb`` (cleared before each),
    each waited for with a 1-pixel read, after one more that compiles llvmpipe's variant.
    ``depth_test``: LESS_EQUAL, writing depth (``fb`` has a depth target)."""
    import gpu
    times = []
    with fb.bind():
        gpu.state.viewport_set(0, 0, width, height)
        gpu.state.depth_test_set('LESS_EQUAL' if depth_test else 'NONE')
        gpu.state.depth_mask_set(depth_test)
        gpu.state.blend_set('NONE')
        for _ in range(repeat + 1):
            if depth_test:
                fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            shader.bind()
            for name, texture in dict(samplers).items():
                shader.uniform_sampler(name, texture)
            start = time.perf_counter()
            batch.draw(shader)
            if depth_test:
                fb.read_depth(0, 0, 1, 1)
            else:
                fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')
            times.append(time.perf_counter() - start)
        gpu.state.depth_test_set('NONE')
        gpu.state.depth_mask_set(False)
    return statistics.median(times[1:])


def _grid(triangles):
    """An n x n grid of quads over most of the screen, at least ``triangles`` triangles:
    positions (clip space, z 0.5) and their indices."""
    import numpy as np
    n = max(1, int(np.ceil(np.sqrt(triangles / 2.0))))
    xs = np.linspace(-0.95, 0.95, n + 1, dtype=np.float32)
    x, y = np.meshgrid(xs, xs)
    positions = np.stack([x.ravel(), y.ravel(), np.full(x.size, 0.5, np.float32)], 1)
    corner = np.arange((n + 1) * n).reshape(n, n + 1)[:, :n].ravel()
    right, up = corner + 1, corner + n + 1
    indices = np.concatenate([np.stack([corner, right, up + 1], 1),
                              np.stack([corner, up + 1, up], 1)]).astype(np.int32)
    return positions, indices


def _grid_shader(targets, varyings):
    import gpu
    info = gpu.types.GPUShaderCreateInfo()
    info.vertex_in(0, 'VEC3', "pos")
    vertex, fragment = "gl_Position = vec4(pos, 1.0);", "vec4 v = vec4(gl_FragCoord.z);"
    if varyings:
        # Ten interpolated values, as the G-buffer's vertex stage hands on.
        interface = gpu.types.GPUStageInterfaceInfo("grid_interface")
        interface.smooth('VEC3', "world_position")
        interface.smooth('VEC3', "world_normal")
        interface.smooth('VEC4', "extra")
        info.vertex_out(interface)
        vertex += (" world_position = pos * 2.0; world_normal = pos.yzx;"
                   " extra = vec4(pos.xy, pos.yx);")
        fragment += " v += vec4(world_position, 1.0) + vec4(normalize(world_normal), 0.0) + extra;"
    for slot, (kind, _format) in enumerate(targets):
        info.fragment_out(slot, kind, f"out_{slot}")
        fragment += f" out_{slot} = " + ("v;" if kind == 'VEC4' else "v.xy;")
    info.vertex_source(f"void main() {{ {vertex} }}")
    info.fragment_source(f"void main() {{ {fragment} }}")
    return gpu.shader.create_from_info(info)


# The G-buffer's two packed targets (gbuffer_layout.glsl).
GBUFFER_TARGETS = (('VEC4', 'RGBA32F'), ('VEC2', 'RG32F'))


def triangle_floor(width, height, triangles, repeat=9):
    """Median seconds of drawing a grid of ``triangles`` small triangles over the screen
    (each waited for): {"depth only": a shadow map's draw, "two colour targets": with the
    G-buffer's targets written, "two colour targets and ten values": with its
    interpolated values too, "depth only, outside the view": the grid moved beside the
    view, every triangle clipped away}. No material, no overdraw: the least a pass of
    that many visible triangles costs here."""
    import gpu
    import numpy as np
    from gpu_extras.batch import batch_for_shader
    positions, indices = _grid(triangles)
    depth = gpu.types.GPUTexture((width, height), format='DEPTH_COMPONENT32F')
    beside = positions + np.array([3.0, 0.0, 0.0], dtype=np.float32)
    out = {}
    for name, targets, varyings, where in (
            ("depth only", (), False, positions),
            ("two colour targets", GBUFFER_TARGETS, False, positions),
            ("two colour targets and ten values", GBUFFER_TARGETS, True, positions),
            ("depth only, outside the view", (), False, beside)):
        shader = _grid_shader(targets, varyings)
        batch = batch_for_shader(shader, 'TRIS', {"pos": where}, indices=indices)
        colors = [gpu.types.GPUTexture((width, height), format=f) for _kind, f in targets]
        fb = gpu.types.GPUFrameBuffer(depth_slot=depth, color_slots=colors)
        out[name] = _median_draw_seconds(fb, shader, batch, width, height, repeat,
                                         depth_test=True)
    return out


def budget_rows(results):
    """Per scene with a camera-animation split: the budget and its parts, in seconds."""
    rows = []
    for scene in results["scenes"]:
        split = scene.get("flythrough_split_s")
        eevee = scene.get("eevee", {}).get("flythrough_s")
        if not split or not eevee:
            continue
        budget = eevee / TARGET_RATIO
        geometry = sum(split[k] for k in GEOMETRY_STEPS)
        fixed = sum(split.get(k, 0.0) for k in FIXED_STEPS)
        rows.append({"name": scene["name"], "budget": budget, "geometry": geometry,
                     "fixed": fixed, "left": budget - geometry - fixed,
                     "shading": sum(split[k] for k in SHADING_STEPS)})
    return rows


def budget_markdown(results):
    """The budget table and what it says, as markdown lines (none without rows)."""
    rows = budget_rows(results)
    if not rows:
        return []
    ms = lambda seconds: f"{seconds * 1000:,.0f}"       # noqa: E731
    minimal = results.get("minimal_pass_s")
    out = ["", f"### What a camera-animation frame at {TARGET_RATIO:.0f}x EEVEE leaves for "
           "shading (ms, from the profiled split above)", "",
           f"| scene | EEVEE's frame / {TARGET_RATIO:.0f} | shadow maps + G-buffer | "
           "scene, meshes, planning, visible depth, read-back, Blender | left for AO, "
           "lighting, FXAA | AO + lighting + FXAA now |",
           "|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        out.append(f"| {row['name']} | {ms(row['budget'])} | {ms(row['geometry'])} | "
                   f"{ms(row['fixed'])} | {ms(row['left'])} | {ms(row['shading'])} |")
    if minimal:
        out += ["", f"The least a full-screen pass costs at this size (read the two packed "
                f"G-buffer targets, write one RGBA32F target, no shading): "
                f"**{minimal * 1000:.1f} ms** (`frame_budget.minimal_pass_seconds`)."]
    return out


def main(argv=None):
    """``./dev frame-floor``: the least a full-screen pass and a pass of N triangles cost
    here, printed in milliseconds."""
    parser = argparse.ArgumentParser(prog="./dev frame-floor", description=main.__doc__)
    parser.add_argument("--resolution", default="1280x720", help="image size (WxH)")
    parser.add_argument("--triangles", type=int, default=252_000,
                        help="triangles in the grid (default: the benchmark's field)")
    args = parser.parse_args(argv)
    from csm_engine.blender.cli import CLIError, parse_resolution
    try:
        width, height = parse_resolution(args.resolution)
        if args.triangles < 2:
            raise CLIError(f"--triangles: needs at least 2, got {args.triangles}")
    except CLIError as error:
        print(f"./dev frame-floor: {error}", file=sys.stderr)
        return 2
    import bpy
    # Blender's GPU module draws once a render made its context: a tiny Workbench one.
    render = bpy.context.scene.render
    render.engine = 'BLENDER_WORKBENCH'
    render.resolution_x, render.resolution_y, render.resolution_percentage = 32, 18, 100
    bpy.ops.render.render()
    print(f"{width}x{height}, a minimal full-screen pass: "
          f"{minimal_pass_seconds(width, height) * 1000:.1f} ms")
    for name, seconds in triangle_floor(width, height, args.triangles).items():
        print(f"{args.triangles:,} triangles, {name}: {seconds * 1000:.1f} ms")
    return 0


if __name__ == "__main__":
    from csm_engine.blender.compat import exit_process
    exit_process(main())
