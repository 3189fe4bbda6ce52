"""The shadow-volume pass: the Exact filter's per-pixel count of the sun's shadow volumes.

Owns ``ShadowVolumes`` (one view's volume geometry, kept between frames: each mesh's
topology by upload, each instance's volume by its mesh, matrix and the sun's direction, and
the one vertex buffer of them all, rebuilt only when one of those changes; a camera move
builds nothing) and ``draw_shadow_volumes``, which counts the volumes into an R32F target
against the G-buffer's view depth (depth-fail without a stencil buffer:
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


def needs_volumes(snap):
    """Whether this frame counts the sun's shadow volumes: Filter Exact, or the Shadow
    error view (which compares the Filter with them), with a sun that casts shadows."""
    settings = snap.settings
    wanted = settings.shadow_filter == "EXACT" or settings.debug_view == "SHADOW_ERROR"
    return wanted and snap.sun is not None and bool(snap.sun.casts_shadow)


def _extrusion(bounds):
    """How far the far caps lie behind their casters: past the scene's diagonal, rounded up
    to a power of two so that an object moving inside the scene keeps the others'
    volumes."""
    if bounds is None:
        return 1.0
    lo, hi = bounds
    diagonal = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
    return 2.0 ** math.ceil(math.log2(max(diagonal * 1.25, 1e-3)))


class ShadowVolumes:
    """One view's volume geometry, kept from frame to frame (see the module docstring).
    ``builds``: instance volumes built so far; ``triangle_count``: triangles in the last
    frame's volumes."""

    def __init__(self):
        self._topologies = {}     # mesh serial -> MeshTopology of its opaque casters
        self._volumes = {}        # (serial, matrix bytes, sun bytes, extrusion) -> soup
        self._batch = None
        self._batch_keys = None
        self.builds = 0
        self.triangle_count = 0

    def _topology(self, mesh):
        topology = self._topologies.get(mesh.serial)
        if topology is None:
            triangles = np.asarray(mesh.triangles).reshape(-1, 3)
            materials = mesh.materials
            if len(materials) and mesh.material_index is not None and len(triangles):
                slots = np.clip(np.asarray(mesh.material_index), 0, len(materials) - 1)
                opaque = np.array([m.shadow_mode == 'OPAQUE' for m in materials])
                triangles = triangles[opaque[slots]]
            topology = geometry.mesh_topology(mesh.positions, triangles)
            self._topologies[mesh.serial] = topology
        return topology

    def batch(self, snap, cache, bounds):
        """The vertex batch of every casting instance's volume for this frame's sun (None
        without any), built only where something changed."""
        import gpu
        to_light = np.asarray(snap.sun.to_light, dtype=np.float64)
        extrusion = _extrusion(bounds)
        keys, meshes = [], []
        for instance in snap.instances:
            mesh = cache.meshes.get(instance.key)
            if not instance.casts_shadow or mesh is None or mesh.positions is None:
                continue
            matrix = np.asarray(instance.world_from_object, dtype=np.float64)
            keys.append((mesh.serial, matrix.tobytes(), to_light.tobytes(), extrusion))
            meshes.append((mesh, matrix))
        keys = tuple(keys)
        if keys == self._batch_keys:
            return self._batch
        volumes, soups = {}, []
        for key, (mesh, matrix) in zip(keys, meshes):
            soup = volumes.get(key)
            if soup is None:
                soup = self._volumes.get(key)
            if soup is None:
                soup = geometry.sun_volume(self._topology(mesh), matrix, to_light, extrusion)
                self.builds += 1
            volumes[key] = soup
            soups.append(soup)
        self._volumes = volumes
        live = {key[0] for key in keys}
        self._topologies = {s: t for s, t in self._topologies.items() if s in live}
        vertices = np.concatenate(soups) if soups else np.zeros((0, 3), np.float32)
        self.triangle_count = len(vertices) // 3
        self._batch = None
        if len(vertices):
            fmt = gpu.types.GPUVertFormat()
            fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
            vbo = gpu.types.GPUVertBuf(fmt, len(vertices))
            vbo.attr_fill("pos", np.ascontiguousarray(vertices, dtype=np.float32))
            self._batch = gpu.types.GPUBatch(type='TRIS', buf=vbo)
        self._batch_keys = keys
        return self._batch


def draw_shadow_volumes(targets, volumes, snap, cache, bounds, frame_ubo, gbuffer, width,
                        height):
    """Count the sun's shadow volumes (``volumes``: this view's ``ShadowVolumes``) behind
    each pixel of ``gbuffer`` into an R32F texture, which it returns: above zero in
    shadow."""
    import gpu
    count = targets.texture("volume_count", (width, height), 'R32F')
    framebuffer = targets.framebuffer("volume_count", colors=(count,))
    batch = volumes.batch(snap, cache, bounds)
    with framebuffer.bind():
        gpu.state.viewport_set(0, 0, width, height)
        targets.call(framebuffer.clear, color=(0.0, 0.0, 0.0, 0.0))
        if batch is not None:
            program = shaders.LIBRARY.get("shadow_volume")
            gpu.state.depth_test_set('NONE')
            gpu.state.depth_mask_set(False)
            gpu.state.face_culling_set('NONE')
            gpu.state.blend_set('ADDITIVE_PREMULT')
            program.bind()
            program.uniform_block("frame", frame_ubo)
            program.uniform_sampler("gbuffer_depth", gbuffer.view_depth)
            targets.call(batch.draw, program)
            gpu.state.blend_set('NONE')
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
