"""Generate the committed sample data in ``data/``: meshes (glTF) and scene files (JSON).

Owns every file under ``csm_engine/data/gltf/`` and ``csm_engine/data/scenes/``. The output is deterministic:
terrain noise comes from an integer hash (no random generator state), floats are
rounded before they are written, and PNG/JSON are written byte by byte, so running the
script twice gives identical files.

    python tools/make_scenes.py                 # regenerate data/ (default size)
    python tools/make_scenes.py --size 176      # a landscape 176 voxels across (4x area)
    python tools/make_scenes.py --out /tmp/big  # write somewhere else

Only numpy and the standard library are needed (PNG via zlib + struct).
"""

import argparse
import json
import math
import os
import re
import sys

import numpy as np

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO_ROOT, "tools"))
from csm_tools.report_io import png_bytes  # noqa: E402  (the one PNG writer)

# The course's vokselia.gltf is about +-1.93 wide in x and z and 0..0.66 high: 88 columns
# of 0.0439-unit voxels span 3.86, and 15 layers reach 0.658.
DEFAULT_COLUMNS = 88
VOXEL_SIZE = 3.86 / DEFAULT_COLUMNS
LAYERS = 15
WATER_LAYERS = 3

# Palette: one 4x4-texel block per (material, shade) so that the first mip levels stay
# pure colours and sampling at block centres never bleeds into a neighbour.
BLOCK = 4
SHADES = 4
MATERIALS = [  # name, base colour (sRGB 0..255)
    ("empty", (255, 0, 255)),
    ("grass", (96, 152, 56)),
    ("dirt", (124, 88, 56)),
    ("stone", (128, 128, 132)),
    ("snow", (236, 240, 244)),
    ("sand", (218, 200, 140)),
    ("water", (56, 104, 176)),
    ("wood", (104, 72, 40)),
    ("leaves", (52, 112, 44)),
    ("brick", (168, 92, 72)),
]
MATERIAL = {name: index for index, (name, _) in enumerate(MATERIALS)}
PALETTE_COLUMNS = 16


# ------------------------------------------------------------------------ noise

def _hash(ix, iz, seed):
    """Deterministic 32-bit integer hash of lattice points (vectorized, wraps mod 2^32)."""
    h = (np.asarray(ix, dtype=np.int64) * 374761393 + np.asarray(iz, dtype=np.int64) * 668265263
         + seed * 2246822519) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    return (h ^ (h >> 16)) & 0xFFFFFFFF


def _unit_hash(ix, iz, seed):
    return _hash(ix, iz, seed).astype(np.float64) / 4294967296.0


def _value_noise(x, z, seed):
    ix, iz = np.floor(x).astype(np.int64), np.floor(z).astype(np.int64)
    fx, fz = x - ix, z - iz
    fx, fz = fx * fx * (3 - 2 * fx), fz * fz * (3 - 2 * fz)
    a = _unit_hash(ix, iz, seed)
    b = _unit_hash(ix + 1, iz, seed)
    c = _unit_hash(ix, iz + 1, seed)
    d = _unit_hash(ix + 1, iz + 1, seed)
    return (a * (1 - fx) + b * fx) * (1 - fz) + (c * (1 - fx) + d * fx) * fz


def _fbm(x, z, seed, octaves=4):
    total, amplitude, norm = 0.0, 1.0, 0.0
    for octave in range(octaves):
        total = total + amplitude * _value_noise(x * 2 ** octave, z * 2 ** octave, seed + octave)
        norm += amplitude
        amplitude *= 0.5
    return total / norm


# -------------------------------------------------------------------- landscape

def _voxel_world(columns):
    """Material index per voxel, shape (columns, LAYERS, columns) as [x, y, z]."""
    half = columns // 2
    g = np.arange(columns) - half          # global voxel coordinate: same world at any size
    gx, gz = np.meshgrid(g, g, indexing="ij")
    rolling = _fbm(gx / 22.0, gz / 22.0, seed=11)
    ridges = 1.0 - np.abs(2.0 * _fbm(gx / 30.0, gz / 30.0, seed=23, octaves=3) - 1.0)
    # Low ground and a shore on the west (-x), where the course camera stands; hills and
    # rocky ridges grow towards the east.
    east = 0.5 + 0.5 * np.tanh((gx + 8) / 18.0)
    shore = np.clip((-30.0 - gx) / 8.0, 0.0, 1.0)
    height = (0.35 + 0.3 * east) * rolling + east * 0.6 * ridges ** 3 - 0.2 * shore + 0.08
    top = np.clip(np.round(height * (LAYERS - 3)), 1, LAYERS - 3).astype(np.int64)
    forest = _fbm(gx / 14.0, gz / 14.0, seed=31, octaves=2)

    y = np.arange(LAYERS)[None, :, None]
    t = top[:, None, :]
    world = np.zeros((columns, LAYERS, columns), dtype=np.uint8)
    solid = y < t
    world[solid] = MATERIAL["dirt"]
    world[solid & (y < t - 3)] = MATERIAL["stone"]
    surface = y == t - 1
    world[surface & (t >= 10)] = MATERIAL["stone"]
    world[surface & (t < 10)] = MATERIAL["grass"]
    world[surface & (t >= 12)] = MATERIAL["snow"]
    world[surface & (t <= WATER_LAYERS)] = MATERIAL["sand"]
    # Lakes: fill low columns up to the water level.
    water = (y >= t) & (y < WATER_LAYERS)
    world[water] = MATERIAL["water"]

    # Trees: at most one per 7x7 cell, jittered, only on grass.
    cell = 6
    for cx in range(math.floor(g[0] / cell), math.floor(g[-1] / cell) + 1):
        for cz in range(math.floor(g[0] / cell), math.floor(g[-1] / cell) + 1):
            if _unit_hash(cx, cz, 101) > 0.8:
                continue
            px = cx * cell + 1 + int(_hash(cx, cz, 102) % (cell - 2)) + half
            pz = cz * cell + 1 + int(_hash(cx, cz, 103) % (cell - 2)) + half
            if not (2 <= px < columns - 2 and 2 <= pz < columns - 2):
                continue
            base = int(top[px, pz])
            # Keep the meadow in front of the course camera open.
            if px - half < -8 and forest[px, pz] < 0.7:
                continue
            if forest[px, pz] < 0.48 or world[px, base - 1, pz] != MATERIAL["grass"]:
                continue
            trunk = 3 + int(_hash(cx, cz, 104) % 2)
            crown = base + trunk
            if crown + 1 >= LAYERS:
                continue
            for layer, radius in ((crown - 2, 2), (crown - 1, 2), (crown, 1), (crown + 1, 0)):
                for dx in range(-radius, radius + 1):
                    for dz in range(-radius, radius + 1):
                        if radius == 2 and abs(dx) == 2 and abs(dz) == 2:
                            continue
                        if world[px + dx, layer, pz + dz] == 0:
                            world[px + dx, layer, pz + dz] = MATERIAL["leaves"]
            world[px, base:crown, pz] = MATERIAL["wood"]

    # Towers: the tallest casters, full height, with a crenellated top.
    for tx, tz in ((-12, 6), (12, -14), (26, 20), (-2, -26)):
        px, pz = tx + half, tz + half
        if not (1 <= px < columns - 1 and 1 <= pz < columns - 1):
            continue
        world[px - 1:px + 2, 0:LAYERS - 1, pz - 1:pz + 2] = MATERIAL["brick"]
        for dx, dz in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
            world[px + dx, LAYERS - 1, pz + dz] = MATERIAL["brick"]
    return world


def _shade(i, y, k):
    return (_hash(i * 31 + y, k, 7) % SHADES).astype(np.int64)


def _landscape_mesh(world):
    """Exposed voxel faces only, flat normals, palette UVs at block centres."""
    columns = world.shape[0]
    solid = world > 0
    padded = np.pad(solid, 1, constant_values=False)
    origin = np.array([-columns / 2.0, 0.0, -columns / 2.0])
    positions, normals, uvs = [], [], []
    for axis in range(3):
        for sign in (1, -1):
            shift = [slice(1, -1)] * 3
            shift[axis] = slice(1 + sign, padded.shape[axis] - 1 + sign)
            exposed = solid & ~padded[tuple(shift)]
            if axis == 1 and sign == -1:
                exposed[:, 0, :] = False   # the underside of the world is never seen
            i, y, k = np.nonzero(exposed)
            cells = np.stack([i, y, k], axis=1).astype(np.float64)
            if sign > 0:
                u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
            else:
                u_axis, v_axis = (axis + 2) % 3, (axis + 1) % 3
            base = cells.copy()
            if sign > 0:
                base[:, axis] += 1.0
            u = np.zeros(3)
            u[u_axis] = 1.0
            v = np.zeros(3)
            v[v_axis] = 1.0
            corners = np.stack([base, base + u, base + u + v, base + v], axis=1)
            positions.append(((corners + origin) * VOXEL_SIZE).reshape(-1, 3))
            normal = np.zeros(3)
            normal[axis] = sign
            normals.append(np.broadcast_to(normal, (len(i) * 4, 3)))
            material = world[i, y, k].astype(np.int64)
            shade = _shade(i, y, k)
            texel_u = (material * BLOCK + BLOCK / 2.0) / (PALETTE_COLUMNS * BLOCK)
            texel_v = (shade * BLOCK + BLOCK / 2.0) / (SHADES * BLOCK)
            uv = np.stack([texel_u, texel_v], axis=1)
            uvs.append(np.repeat(uv, 4, axis=0))
    positions = np.concatenate(positions).astype(np.float32)
    normals = np.concatenate(normals).astype(np.float32)
    uvs = np.concatenate(uvs).astype(np.float32)
    quads = len(positions) // 4
    first = (np.arange(quads, dtype=np.uint32) * 4)[:, None]
    indices = (first + np.array([0, 1, 2, 0, 2, 3], dtype=np.uint32)).reshape(-1)
    return positions, normals, uvs, indices


def _palette_png():
    width, height = PALETTE_COLUMNS * BLOCK, SHADES * BLOCK
    image = np.zeros((height, width, 3), dtype=np.uint8)
    for index, (_, colour) in enumerate(MATERIALS):
        for shade in range(SHADES):
            factor = 0.86 + 0.06 * shade   # subtle per-voxel variation
            value = np.clip(np.round(np.array(colour) * factor), 0, 255).astype(np.uint8)
            image[shade * BLOCK:(shade + 1) * BLOCK, index * BLOCK:(index + 1) * BLOCK] = value
    return png_bytes(image)


# ------------------------------------------------------------------------ glTF

class _GltfBuilder:
    """Collects binary views and accessors for one .gltf + .bin pair."""

    def __init__(self):
        self.blob = bytearray()
        self.views = []
        self.accessors = []

    def add(self, array, component, kind, target, with_bounds=False):
        while len(self.blob) % 4:
            self.blob.append(0)
        data = np.ascontiguousarray(array).tobytes()
        self.views.append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data),
                           "target": target})
        self.blob.extend(data)
        accessor = {"bufferView": len(self.views) - 1, "componentType": component,
                    "count": int(len(array)), "type": kind}
        if with_bounds:
            accessor["min"] = [float(v) for v in np.min(array, axis=0)]
            accessor["max"] = [float(v) for v in np.max(array, axis=0)]
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def primitive(self, positions, normals, indices, uvs=None, material=0):
        attributes = {
            "POSITION": self.add(positions, 5126, "VEC3", 34962, with_bounds=True),
            "NORMAL": self.add(normals, 5126, "VEC3", 34962),
        }
        if uvs is not None:
            attributes["TEXCOORD_0"] = self.add(uvs, 5126, "VEC2", 34962)
        component = 5125 if indices.dtype == np.uint32 else 5123
        return {"attributes": attributes,
                "indices": self.add(indices, component, "SCALAR", 34963),
                "material": material}

    def document(self, bin_name, **parts):
        doc = {"asset": {"version": "2.0", "generator": "CSM Engine tools/make_scenes.py"}}
        doc.update(parts)
        doc["accessors"] = self.accessors
        doc["bufferViews"] = self.views
        doc["buffers"] = [{"uri": bin_name, "byteLength": len(self.blob)}]
        return doc


def _write(path, data):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as stream:
        stream.write(data)


def _write_json(path, document):
    _write(path, (json.dumps(document, indent=1) + "\n").encode("utf-8"))


def write_landscape(folder, columns):
    world = _voxel_world(columns)
    positions, normals, uvs, indices = _landscape_mesh(world)
    gltf = _GltfBuilder()
    primitive = gltf.primitive(positions, normals, indices, uvs)
    name = "voxel_landscape"
    document = gltf.document(
        f"{name}.bin",
        scene=0,
        scenes=[{"nodes": [0]}],
        nodes=[{"name": name, "mesh": 0}],
        meshes=[{"name": name, "primitives": [primitive]}],
        materials=[{"name": "voxel palette",
                    "pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
                                             "metallicFactor": 0.0, "roughnessFactor": 0.9}}],
        textures=[{"sampler": 0, "source": 0}],
        # Nearest filtering: each face samples one palette block centre.
        samplers=[{"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
        images=[{"uri": f"{name}_palette.png"}],
    )
    _write_json(os.path.join(folder, f"{name}.gltf"), document)
    _write(os.path.join(folder, f"{name}.bin"), bytes(gltf.blob))
    _write(os.path.join(folder, f"{name}_palette.png"), _palette_png())
    return world, len(indices) // 3


def _box(low, high):
    """24 vertices (flat normals) and 36 indices of an axis-aligned box."""
    positions, normals = [], []
    low, high = np.asarray(low, float), np.asarray(high, float)
    for axis in range(3):
        for sign in (1, -1):
            u_axis, v_axis = ((axis + 1) % 3, (axis + 2) % 3) if sign > 0 else \
                ((axis + 2) % 3, (axis + 1) % 3)
            base = low.copy()
            if sign > 0:
                base[axis] = high[axis]
            u = np.zeros(3)
            u[u_axis] = high[u_axis] - low[u_axis]
            v = np.zeros(3)
            v[v_axis] = high[v_axis] - low[v_axis]
            positions += [base, base + u, base + u + v, base + v]
            normal = np.zeros(3)
            normal[axis] = sign
            normals += [normal] * 4
    indices = np.array([[q * 4, q * 4 + 1, q * 4 + 2, q * 4, q * 4 + 2, q * 4 + 3]
                        for q in range(6)], dtype=np.uint16).reshape(-1)
    return np.array(positions, np.float32), np.array(normals, np.float32), indices


PILLAR_COUNT = 39
PILLAR_SPACING = 5.0


def write_shadow_test(folder):
    gltf = _GltfBuilder()
    ground = gltf.primitive(np.array([[-110, 0, -40], [-110, 0, 40], [110, 0, 40], [110, 0, -40]],
                                     np.float32),
                            np.array([[0, 1, 0]] * 4, np.float32),
                            np.array([0, 1, 2, 0, 2, 3], np.uint16), material=0)
    cube = gltf.primitive(*_box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)), material=1)
    nodes = [{"name": "ground", "mesh": 0}]
    for index in range(PILLAR_COUNT):
        x = (index - PILLAR_COUNT // 2) * PILLAR_SPACING
        nodes.append({"name": f"pillar_{index:02d}", "mesh": 1,
                      "translation": [x, 1.5, 0.0], "scale": [1.0, 3.0, 1.0]})
    document = gltf.document(
        "shadow_test.bin",
        scene=0,
        scenes=[{"nodes": list(range(len(nodes)))}],
        nodes=nodes,
        meshes=[{"name": "ground", "primitives": [ground]},
                {"name": "unit_cube", "primitives": [cube]}],
        materials=[
            {"name": "ground", "pbrMetallicRoughness": {
                "baseColorFactor": [0.55, 0.55, 0.55, 1.0], "metallicFactor": 0.0,
                "roughnessFactor": 0.8}},
            {"name": "pillar", "pbrMetallicRoughness": {
                "baseColorFactor": [0.8, 0.72, 0.6, 1.0], "metallicFactor": 0.0,
                "roughnessFactor": 0.5}},
        ],
    )
    _write_json(os.path.join(folder, "shadow_test.gltf"), document)
    _write(os.path.join(folder, "shadow_test.bin"), bytes(gltf.blob))


# ---------------------------------------------------------------------- scenes

def _vec(x, y, z):
    return {"x": _tidy(x), "y": _tidy(y), "z": _tidy(z)}


def _tidy(value):
    value = round(float(value), 2)
    return int(value) if value == int(value) else value


def camera_rotate_looking_at(eye, target):
    """The file's camera ``rotate`` (degrees, z = 0) that looks from eye to target.

    With view = Rx * Ry * Rz * T(-eye) the camera looks along
    (sin(ry) cos(rx), -sin(rx), -cos(ry) cos(rx)) in the file's Y-up world.
    """
    forward = np.asarray(target, float) - np.asarray(eye, float)
    forward /= np.linalg.norm(forward)
    rx = math.degrees(math.asin(-forward[1]))
    ry = math.degrees(math.atan2(forward[0], -forward[2]))
    return round(rx, 1), round(ry, 1), 0.0


def _camera(eye, rotate, fov, near, far):
    return {"translate": _vec(*eye), "rotate": _vec(*rotate),
            "near": near, "far": far, "FOVy": fov}


def _object(mesh, scale=1.0, translate=(0, 0, 0)):
    return {"mesh": mesh, "translate": _vec(*translate), "rotate": _vec(0, 0, 0),
            "scale": _vec(scale, scale, scale)}


def _scene_text(scene):
    """Course-style layout: one {x, y, z} per line, sections separated."""
    text = json.dumps(scene, indent=4)
    # Put each small {"x":..,"y":..,"z":..} object on one line, as the course files do.
    return re.sub(r'\{\s*"x": ([^,]+),\s*"y": ([^,]+),\s*"z": ([^\s}]+)\s*\}',
                  r'{ "x": \1, "y": \2, "z": \3 }', text) + "\n"


def _surface_height(world, x, z, scale):
    """Top of the voxels below file position (x, z) of the landscape scaled by ``scale``."""
    columns = world.shape[0]
    i = int(math.floor(x / scale / VOXEL_SIZE + columns / 2))
    k = int(math.floor(z / scale / VOXEL_SIZE + columns / 2))
    i, k = min(max(i, 0), columns - 1), min(max(k, 0), columns - 1)
    filled = np.nonzero(world[i, :, k])[0]
    return (filled.max() + 1 if len(filled) else 0) * VOXEL_SIZE * scale


def write_scenes(folder, world):
    landscape = "../gltf/voxel_landscape/voxel_landscape.gltf"
    default = {
        # The course's sceneShadow camera: it stands on the low west shore and looks
        # east (+x) across the landscape.
        "camera": _camera((-190, 40, 50), (0, 100, 0), 30.0, 0.1, 500.0),
        "objects": [_object(landscape, 100)],
        "lights": [],
        "directional_light": {"direction": _vec(0.3, -0.6, -0.7), "color": _vec(1, 1, 1)},
    }
    _write(os.path.join(folder, "default.json"), _scene_text(default).encode("utf-8"))

    eye, target = (-40.0, 14.0, 26.0), (-5.0, 0.0, -4.0)
    shadow_test = {
        "camera": _camera(eye, camera_rotate_looking_at(eye, target), 45.0, 0.1, 300.0),
        "objects": [_object("../gltf/shadow_test/shadow_test.gltf")],
        "lights": [],
        "directional_light": {"direction": _vec(0.3, -0.6, -0.7), "color": _vec(1, 1, 1)},
    }
    _write(os.path.join(folder, "shadow_test.json"), _scene_text(shadow_test).encode("utf-8"))

    scale = 40.0
    colours = [(1.0, 0.35, 0.2), (0.3, 1.0, 0.35), (0.3, 0.5, 1.0),
               (1.0, 0.85, 0.3), (1.0, 0.3, 0.9), (0.3, 1.0, 1.0)]
    spots = [(-40, -30), (-35, 25), (0, 0), (10, -35), (35, 20), (45, -10)]
    lights = []
    for (x, z), colour in zip(spots, colours):
        y = _surface_height(world, x, z, scale) + 6.0
        lights.append({"position": _vec(x, y, z), "color": _vec(*colour), "radius": 30})
    eye, target = (-95.0, 70.0, 85.0), (0.0, 5.0, 0.0)
    point_lights = {
        "camera": _camera(eye, camera_rotate_looking_at(eye, target), 45.0, 0.5, 400.0),
        "objects": [_object(landscape, scale)],
        "lights": lights,
        # A faint moonlight so the unlit ground still reads; the point lights dominate.
        "directional_light": {"direction": _vec(0.3, -0.6, -0.7), "color": _vec(0.06, 0.07, 0.1)},
    }
    _write(os.path.join(folder, "point_lights.json"), _scene_text(point_lights).encode("utf-8"))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=DEFAULT_COLUMNS,
                        help=f"landscape columns per side (default {DEFAULT_COLUMNS}; the "
                             "voxel size stays the same, so larger sizes make a larger world)")
    parser.add_argument("--out", default=os.path.join(REPO_ROOT, "csm_engine", "data"),
                        help="data folder to write into (default: csm_engine/data)")
    args = parser.parse_args(argv)
    if args.size < 8:
        parser.error("--size must be at least 8")
    out = os.path.abspath(args.out)
    world, triangles = write_landscape(os.path.join(out, "gltf", "voxel_landscape"), args.size)
    write_shadow_test(os.path.join(out, "gltf", "shadow_test"))
    write_scenes(os.path.join(out, "scenes"), world)
    print(f"wrote {out}: voxel landscape {args.size}x{LAYERS}x{args.size} voxels, "
          f"{triangles} triangles")
    return 0


if __name__ == "__main__":
    sys.exit(main())
