"""The shadow-volume pass: the Exact filter's per-pixel count of the lights' shadow volumes.

Owns ``volume_lights`` (which lights a frame counts: the sun, and with Filter Exact the
first three shadowed point and spot lights), ``ShadowVolumes`` (one view's volume geometry,
kept between frames: each mesh's topology by upload, each instance's volume by its mesh,
matrix and the light's direction or position, and one vertex buffer per light, rebuilt only
when one of those changes; a camera move builds nothing) and ``draw_shadow_volumes``, which
counts the volumes into an RGBA32F target, a light per channel, against the G-buffer's view
depth (depth-fail without a stencil buffer:
``shadow_volume_frag.glsl``). The geometry comes from ``core/shadow_volumes.py``. Also
owns ``ShadowError`` and ``shadow_error``: the Shadow error view's share of surface pixels
whose Filter shadow is false or missed, counted from the view's own pixels.

What casts: instances that cast shadows, and of their triangles those whose material
casts an opaque shadow; alpha-clipped and hashed shadows are left out (the setting's
description says so).
"""

import math
from typing import NamedTuple

import numpy as np

from ..core import shadow_volumes as geometry
from . import shaders


# Channels of the count target: the sun's count in the first, then the first shadowed
# local lights' (point lights with shadows first, then shadowed spots in order), as
# shadow_volume_lookup.glsl reads them.
LOCAL_LIGHT_CHANNELS = 3


class VolumeLight(NamedTuple):
    """One light whose volumes a frame counts: "SUN" with the unit vector towards it, or
    "POINT" (point and spot lights) with its position; ``channel`` of the count target."""
    kind: str
    vector: tuple
    channel: int


def volume_lights(snap, plan):
    """The lights this frame counts volumes for (``VolumeLight``): with Filter Exact the
    shadow-casting sun and the first ``LOCAL_LIGHT_CHANNELS`` shadowed point and spot
    lights of ``plan`` (the ones that have shadow maps); in the Shadow error view the sun
    too. None are counted in any other frame."""
    settings = snap.settings
    exact = settings.shadow_filter == "EXACT"
    lights = []
    if (exact or settings.debug_view == "SHADOW_ERROR") and snap.sun is not None and \
            snap.sun.casts_shadow:
        lights.append(VolumeLight("SUN", tuple(map(float, snap.sun.to_light)), 0))
    if exact and plan is not None:
        local = [snap.points[i].position for i in range(plan.point_shadow_count)]
        local += [snap.spots[i].position for i in sorted(plan.spot_tiles)]
        for channel, position in enumerate(local[:LOCAL_LIGHT_CHANNELS], start=1):
            lights.append(VolumeLight("POINT", tuple(map(float, position)), channel))
    return lights


def _receivers_box(bounds):
    """The box every receiver lies in, for the sun's far caps: the scene's bounds grown
    outward to a grid an eighth of its diagonal (a power of two), so that an object moving
    inside the scene keeps the other objects' volumes."""
    if bounds is None:
        return ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    step = 2.0 ** math.ceil(math.log2(max(float(np.linalg.norm(hi - lo)) / 8.0, 1e-3)))
    return (tuple(np.floor(lo / step) * step - step), tuple(np.ceil(hi / step) * step + step))


def _reach(bounds, position):
    """The farthest a receiver can be from a light at ``position``: the scene bounds'
    farthest corner, rounded up to a power of two (see ``_receivers_box``)."""
    if bounds is None:
        return 1.0
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    farthest = float(np.linalg.norm(corners - np.asarray(position), axis=1).max())
    return 2.0 ** math.ceil(math.log2(max(farthest * 1.05, 1e-3)))


class ShadowVolumes:
    """One view's volume geometry, kept from frame to frame (see the module docstring).
    ``builds``: instance volumes built so far; ``triangle_count``: triangles in the last
    frame's volumes, all lights together."""

    def __init__(self):
        self._topologies = {}     # (mesh serial, shadow modes) -> MeshTopology of its
        #                           opaque casters
        self._volumes = {}        # (serial, shadow modes, matrix bytes, light, extent)
        #                           -> Volume
        self._batches = {}        # channel -> (keys, batch, triangles)
        self.builds = 0
        # What the count texture holds: (texture, G-buffer depth, ``contents``).
        self.held_count = None
        self.counts_kept = 0      # frames whose counts were kept (tests)

    @property
    def triangle_count(self):
        return sum(triangles for _keys, _batch, triangles in self._batches.values())

    def contents(self, lights):
        """What the volumes of ``lights`` are made of, as a value (per channel the keys of
        its instances' volumes), after ``batches`` built them."""
        return tuple((light.channel, self._batches[light.channel][0]) for light in lights)

    def _topology(self, mesh):
        # A material edit may change which slots cast without a new upload.
        key = (mesh.serial, tuple(m.shadow_mode for m in mesh.materials))
        topology = self._topologies.get(key)
        if topology is None:
            triangles = np.asarray(mesh.triangles).reshape(-1, 3)
            materials = mesh.materials
            if len(materials) and mesh.material_index is not None and len(triangles):
                slots = np.clip(np.asarray(mesh.material_index), 0, len(materials) - 1)
                opaque = np.array([m.shadow_mode == 'OPAQUE' for m in materials])
                triangles = triangles[opaque[slots]]
            topology = geometry.mesh_topology(mesh.positions, triangles)
            self._topologies[key] = topology
        return topology

    def batches(self, snap, cache, bounds, lights):
        """Per light of ``lights`` (``VolumeLight``), the vertex batch of every casting
        instance's volume (None without any), built only where something changed."""
        casting = []
        for instance in snap.instances:
            mesh = cache.meshes.get(instance.key)
            if not instance.casts_shadow or mesh is None or mesh.positions is None:
                continue
            matrix = np.asarray(instance.world_from_object, dtype=np.float64)
            casting.append((mesh, matrix, matrix.tobytes()))
        volumes, batches, result = {}, {}, []
        for light in lights:
            extent = _receivers_box(bounds) if light.kind == "SUN" else \
                _reach(bounds, light.vector)
            keys = tuple((mesh.serial, tuple(m.shadow_mode for m in mesh.materials),
                          matrix_bytes, light.kind, light.vector, extent)
                         for mesh, _matrix, matrix_bytes in casting)
            held = self._batches.get(light.channel)
            if held is not None and held[0] == keys:
                batches[light.channel] = held
                for key in keys:
                    volumes[key] = self._volumes[key]
                result.append(held[1])
                continue
            parts = []
            for key, (mesh, matrix, _bytes) in zip(keys, casting):
                volume = volumes.get(key)
                if volume is None:
                    volume = self._volumes.get(key)
                if volume is None:
                    topology = self._topology(mesh)
                    if light.kind == "SUN":
                        volume = geometry.sun_volume(topology, matrix, light.vector, extent)
                    else:
                        volume = geometry.point_volume(topology, matrix, light.vector, extent)
                    self.builds += 1
                volumes[key] = volume
                parts.append(volume)
            batch, triangles = _upload(parts)
            batches[light.channel] = (keys, batch, triangles)
            result.append(batch)
        self._volumes = volumes
        self._batches = batches
        live = {key[:2] for key in volumes}
        self._topologies = {k: t for k, t in self._topologies.items() if k in live}
        return result


def _upload(volumes):
    """One indexed batch of ``core.shadow_volumes.Volume`` s (None when they have no
    triangle), and its triangle count."""
    import gpu
    triangles = sum(len(volume.triangles) for volume in volumes)
    if not triangles:
        return None, 0
    offsets = np.cumsum([0] + [len(volume.vertices) for volume in volumes[:-1]])
    vertices = np.concatenate([volume.vertices for volume in volumes])
    indices = np.concatenate([volume.triangles + np.int32(offset)
                              for volume, offset in zip(volumes, offsets)])
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
    vbo = gpu.types.GPUVertBuf(fmt, len(vertices))
    vbo.attr_fill("pos", np.ascontiguousarray(vertices, dtype=np.float32))
    ibo = gpu.types.GPUIndexBuf(type='TRIS', seq=np.ascontiguousarray(indices, np.int32))
    return gpu.types.GPUBatch(type='TRIS', buf=vbo, elem=ibo), triangles


def draw_shadow_volumes(targets, volumes, snap, cache, bounds, lights, frame_ubo, gbuffer,
                        width, height, gbuffer_kept=False):
    """Count the shadow volumes of ``lights`` (``volume_lights``; ``volumes``: this view's
    ``ShadowVolumes``) behind each pixel of ``gbuffer`` into an RGBA32F texture, one light
    per channel, which it returns with its framebuffer: above zero in shadow. With the
    G-buffer kept (``gbuffer_kept``) and the same volumes, the counts the texture holds
    are kept too (a light or filter setting changed, an unchanged re-render)."""
    import gpu
    count = targets.texture("volume_count", (width, height), 'RGBA32F')
    framebuffer = targets.framebuffer("volume_count", colors=(count,))
    batches = volumes.batches(snap, cache, bounds, lights)
    held = (count, gbuffer.view_depth, volumes.contents(lights))
    if gbuffer_kept and targets.records and volumes.held_count == held:
        volumes.counts_kept += 1
        return count, framebuffer
    volumes.held_count = None
    with framebuffer.bind():
        gpu.state.viewport_set(0, 0, width, height)
        targets.call(framebuffer.clear, color=(0.0, 0.0, 0.0, 0.0))
        program = shaders.LIBRARY.get("shadow_volume")
        gpu.state.depth_test_set('NONE')
        gpu.state.depth_mask_set(False)
        gpu.state.face_culling_set('NONE')
        gpu.state.blend_set('ADDITIVE_PREMULT')
        program.bind()
        program.uniform_block("frame", frame_ubo)
        program.uniform_sampler("gbuffer_depth", gbuffer.view_depth)
        for light, batch in zip(lights, batches):
            if batch is None:
                continue
            mask = [0.0, 0.0, 0.0, 0.0]
            mask[light.channel] = 1.0
            program.uniform_float("channel", mask)
            targets.call(batch.draw, program)
        gpu.state.blend_set('NONE')
    if targets.records:
        volumes.held_count = held
    return count, framebuffer


class ShadowError(NamedTuple):
    """What the Shadow error view showed: the shares (0..1) of its surface pixels where the
    Filter shadows what the sun reaches (``false_shadow``) or lights what it does not
    (``missed_shadow``), out of ``surface_pixels``."""
    false_shadow: float
    missed_shadow: float
    surface_pixels: int

    @property
    def label(self):
        return (f"false shadow {100 * self.false_shadow:.2f} %, missed shadow "
                f"{100 * self.missed_shadow:.2f} % of {self.surface_pixels} pixels")


def shadow_error(framebuffer, width, height):
    """Count the Shadow error view's colours (``debug_views.glsl``'s
    ``shadow_error_color``: pure red, pure cyan, grey from 0.2, black background) in
    ``framebuffer`` (None: the bound one). Colours mixed by FXAA at an edge are counted by
    the nearer colour."""
    import gpu
    if framebuffer is None:
        framebuffer = gpu.state.active_framebuffer_get()
    buffer = gpu.types.Buffer('FLOAT', width * height * 4)
    with framebuffer.bind():
        framebuffer.read_color(0, 0, width, height, 4, 0, 'FLOAT', data=buffer)
    rgb = np.frombuffer(buffer, np.float32).reshape(-1, 4)[:, :3]
    red, green, blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    surface = rgb.max(axis=1) > 0.1
    false = (red > 0.6) & (green < 0.3) & (blue < 0.3)
    missed = (red < 0.3) & (green > 0.6) & (blue > 0.6)
    count = int(surface.sum())
    return ShadowError(float(false.sum()) / max(count, 1), float(missed.sum()) / max(count, 1),
                       count)
