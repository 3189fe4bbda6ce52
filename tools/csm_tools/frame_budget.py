"""What a camera-animation frame at 20x EEVEE's speed would leave for shading.

Owns ``minimal_pass_seconds`` (the least a full-screen pass costs at a resolution on this
machine: read the two packed G-buffer targets at each pixel, write one RGBA32F target) and
the benchmark's budget table (``budget_rows``, ``budget_markdown``): per scene, EEVEE's
frame of the same animation divided by 20, less what CSM's frame spends before and around
its shading passes (the shadow maps and the G-buffer, which cost per triangle; reading the
scene and meshes, planning, the visible-depth reduction, read-back and Blender's hand-off),
against what the AO, lighting and FXAA passes spend now.
"""

import statistics
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
    times = []
    with fb.bind():
        gpu.state.viewport_set(0, 0, width, height)
        gpu.state.depth_test_set('NONE')
        gpu.state.blend_set('NONE')
        shader.bind()
        shader.uniform_sampler("surface", surface)
        shader.uniform_sampler("view_depth", view_depth)
        for _ in range(repeat + 1):         # the first draw compiles llvmpipe's variant
            start = time.perf_counter()
            batch.draw(shader)
            fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')
            times.append(time.perf_counter() - start)
    return statistics.median(times[1:])


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
