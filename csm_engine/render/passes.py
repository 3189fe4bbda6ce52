"""The render passes beyond Combined: what a final render draws and derives for them.

Owns ``PassRequest`` (which passes a render asked for), the targets of the light and colour
passes (``LIGHTING_PASS_TARGETS``, written by the PASSES twins of the lighting and
background programs), the Cryptomatte IDs the G-buffer's CRYPTOMATTE twins write
(``cryptomatte_draw_ids``) and their samples (``CryptomatteSamples``), and the passes
derived on the CPU from what was read back (``derived_passes``: Mist, Position,
Environment). A render that asks for none of them draws exactly what it drew without
them: no extra target, program output or read.

Pass names here are Blender 5.0's; ``blender/render_passes.py`` maps them to each host's.
"""

from typing import NamedTuple

import numpy as np

from ..core import cryptomatte

# The PASSES programs' extra targets, in colour slots 2.. of the lit framebuffer (slot 0
# Combined, slot 1 aux; Blender's Python framebuffers take six colour targets at most, so
# the sixteen channels fill four), and where each pass is: name -> (target, channel) per
# channel. Must match lighting_frag.glsl's write_surface_passes.
LIGHTING_PASS_TARGETS = ("pass_diffuse_light", "pass_specular_light", "pass_diffuse_color",
                         "pass_specular_color")
LIGHTING_PASS_CHANNELS = {
    "Diffuse Direct": ((0, 0), (0, 1), (0, 2)),
    "Ambient Occlusion": ((0, 3),),
    "Glossy Direct": ((1, 0), (1, 1), (1, 2)),
    "Diffuse Color": ((2, 0), (2, 1), (2, 2)),
    "Glossy Color": ((3, 0), (3, 1), (3, 2)),
    "Emission": ((1, 3), (2, 3), (3, 3)),
}
LIGHTING_PASSES = frozenset(LIGHTING_PASS_CHANNELS)
# Passes computed from the read-back images: Environment from Combined and coverage, Mist
# and Position from the view depth.
DERIVED_PASSES = frozenset({"Mist", "Position", "Environment"})


class Mist(NamedTuple):
    """World > Mist Pass: where the mist starts and how deep it is (scene units), and its
    falloff ('QUADRATIC', 'LINEAR' or 'INVERSE_QUADRATIC')."""
    start: float = 5.0
    depth: float = 25.0
    falloff: str = "QUADRATIC"


class PassRequest(NamedTuple):
    """The passes a final render writes besides Combined, Shadow and Cascade: ``names``
    (Blender 5.0 names: "Depth", "Normal", "Mist", "Diffuse Direct", ...), the
    Cryptomatte layers (``cryptomatte``: kinds 'OBJECT', 'MATERIAL', 'ASSET') with
    ``cryptomatte_levels`` ranks each, and the World's ``mist`` settings."""
    names: frozenset = frozenset()
    cryptomatte: tuple = ()
    cryptomatte_levels: int = 6
    mist: Mist = Mist()
    view_layer: str = "ViewLayer"

    @property
    def lighting(self):
        """Whether the lighting pass writes its PASSES targets."""
        return bool(self.names & LIGHTING_PASSES)

    @property
    def any(self):
        return bool(self.names or self.cryptomatte)


NO_PASSES = PassRequest()


def lighting_pass_textures(targets, width, height):
    """The PASSES programs' extra targets (float32: light x colour recombines to Combined
    within float precision)."""
    return tuple(targets.texture(name, (width, height), 'RGBA32F')
                 for name in LIGHTING_PASS_TARGETS)


def split_lighting_passes(images):
    """name -> (H, W, C) of the light and colour passes in ``images`` (as read back under
    their target names). The targets hold each layer's reflected light, which samples
    average as they average the colours; a Light pass is that divided by its Color pass,
    as Blender defines Diffuse and Glossy Light (so light x colour gives the averaged
    reflected light back), and 0 where the layer reflects nothing."""
    if any(images.get(target) is None for target in LIGHTING_PASS_TARGETS):
        return {}
    out = {}
    for name, channels in LIGHTING_PASS_CHANNELS.items():
        targets = {target for target, _channel in channels}
        if len(targets) == 1:       # channels in one target, in order: a view, no copy
            first = channels[0][1]
            out[name] = images[LIGHTING_PASS_TARGETS[channels[0][0]]][
                ..., first:first + len(channels)]
        else:
            out[name] = np.stack([images[LIGHTING_PASS_TARGETS[target]][..., channel]
                                  for target, channel in channels], axis=-1)
    for light, color in (("Diffuse Direct", "Diffuse Color"),
                         ("Glossy Direct", "Glossy Color")):
        reflected, layer = out[light], out[color]
        out[light] = np.divide(reflected, layer, out=np.zeros_like(reflected),
                               where=layer > 0.0)
    return out


def view_space_points(camera, view_depth):
    """(H, W, 3) view-space points of the pixel centres at ``view_depth`` (H, W). Blender's
    projections map view x to clip x alone (and y to y), so each pixel's point is its
    column's x and row's y scaled by the depth: a few broadcasts, where a general 4x4
    unprojection of every pixel (``core.camera.world_positions``) costs ~0.5 s at 720p."""
    height, width = view_depth.shape
    clip_from_view = np.asarray(camera.clip_from_view, dtype=np.float64)
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = (np.arange(height) + 0.5) / height * 2.0 - 1.0
    depth = np.asarray(view_depth, dtype=np.float64)
    if camera.is_perspective:
        # clip = (P00 x + P02 z, P11 y + P12 z, .., -z) with z = -depth.
        x_view = (x + clip_from_view[0, 2]) / clip_from_view[0, 0]
        y_view = (y + clip_from_view[1, 2]) / clip_from_view[1, 1]
        return np.stack([x_view[None, :] * depth, y_view[:, None] * depth, -depth], axis=-1)
    x_view = (x - clip_from_view[0, 3]) / clip_from_view[0, 0]
    y_view = (y - clip_from_view[1, 3]) / clip_from_view[1, 1]
    return np.stack(np.broadcast_arrays(x_view[None, :], y_view[:, None], -depth), axis=-1)


def world_points(camera, view_depth):
    """(H, W, 3) world positions of the pixel centres at ``view_depth``: the same points
    as ``core.camera.world_positions``, computed through ``view_space_points``."""
    view = view_space_points(camera, view_depth)
    world_from_view = np.asarray(camera.world_from_view, dtype=np.float64)
    return view @ world_from_view[:3, :3].T + world_from_view[:3, 3]


def mist_pass(snap, view_depth, covered, mist):
    """Blender's Mist pass: 0 at ``mist.start`` from the camera (distance for a
    perspective camera, depth along its axis for an orthographic one), 1 at start + depth
    and beyond (and where no surface is), shaped by the falloff."""
    camera = snap.camera
    depth = np.where(covered, view_depth, 0.0).astype(np.float64)
    if camera.is_perspective:
        distance = np.linalg.norm(view_space_points(camera, depth), axis=-1)
    else:
        distance = depth
    amount = np.clip((distance - mist.start) / max(mist.depth, 1e-9), 0.0, 1.0)
    exponent = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}.get(
        mist.falloff, 2.0)
    amount = amount ** exponent
    return np.where(covered, amount, 1.0).astype(np.float32)[..., None]


def derived_passes(snap, request, images):
    """Mist, Position and Environment from the read-back "combined" and "aux" (view depth
    in z, coverage in w) images, for those ``request`` names."""
    out = {}
    wanted = request.names & DERIVED_PASSES
    if not wanted:
        return out
    aux = images["aux"]
    coverage = aux[..., 3]
    covered = coverage > 0.5
    if "Environment" in wanted:
        # Where no surface is, Combined is the World as the camera sees it.
        out["Environment"] = images["combined"][..., :3] * (1.0 - coverage[..., None])
    if "Mist" in wanted:
        out["Mist"] = mist_pass(snap, aux[..., 2], covered, request.mist)
    if "Position" in wanted:
        depth = np.where(covered, aux[..., 2], 1.0).astype(np.float64)
        position = world_points(snap.camera, depth) * covered[..., None]
        out["Position"] = position.astype(np.float32)
    return out


class DrawIds(NamedTuple):
    """The Cryptomatte IDs the G-buffer writes: per instance (object, asset), per
    material name its ID."""
    per_instance: np.ndarray        # (N, 2) float32
    per_material: dict


def cryptomatte_draw_ids(snap):
    """Each instance's object and asset ID (``MeshInstance.name``, ``.asset``), and a
    memo for materials' IDs (filled as the G-buffer draws them)."""
    per_instance = np.zeros((len(snap.instances), 2), dtype=np.float32)
    for index, instance in enumerate(snap.instances):
        per_instance[index] = (cryptomatte.name_id(instance.name or instance.key),
                               cryptomatte.name_id(instance.asset or instance.name or
                                                   instance.key))
    return DrawIds(per_instance, {})


def material_id(ids, name):
    """The Cryptomatte ID of material ``name`` (0: no material), memoized in ``ids``."""
    value = ids.per_material.get(name)
    if value is None:
        value = ids.per_material[name] = cryptomatte.name_id(name) if name else 0.0
    return value


class CryptomatteSamples:
    """The G-buffer's ID target of each drawn sample of one final render (object,
    material, asset in rgb; 0 where no surface), with the sample's pixel-filter weight."""

    def __init__(self):
        self.images = []
        self.weights = []

    def add(self, image, weight):
        self.images.append(image)
        self.weights.append(float(weight))

    def passes(self, request):
        """pass name -> (H, W, 4): each requested layer's CryptoXxx00.. passes."""
        out = {}
        if not self.images:
            return out
        stack = np.stack(self.images)
        channel = {"OBJECT": 0, "MATERIAL": 1, "ASSET": 2}
        for kind in request.cryptomatte:
            ids, coverage = cryptomatte.rank_coverage(stack[..., channel[kind]], self.weights,
                                                      request.cryptomatte_levels)
            for index, rgba in enumerate(cryptomatte.pack_levels(ids, coverage)):
                out[f"{cryptomatte.LAYER_PASS_NAMES[kind]}{index:02d}"] = rgba
        return out


def cryptomatte_names(snap, material_names):
    """layer kind -> the names its manifest lists: the instances' objects and assets, and
    the materials drawn."""
    return {"OBJECT": sorted({i.name or i.key for i in snap.instances}),
            "ASSET": sorted({i.asset or i.name or i.key for i in snap.instances}),
            "MATERIAL": sorted(name for name in material_names if name)}


def collect(snap, request, images, samples):
    """Every pass ``request`` names, by its (Blender 5.0) name, from the read-back
    ``images`` (the lighting pass targets under their target names, "combined", "aux",
    "normal") and the Cryptomatte ``samples`` (``CryptomatteSamples``)."""
    out = {}
    names = request.names
    split = split_lighting_passes(images)
    out.update({name: image for name, image in split.items() if name in names})
    if "Depth" in names:
        out["Depth"] = images["aux"][..., 2:3]
    if "Normal" in names and "normal" in images:
        out["Normal"] = images["normal"][..., :3]
    out.update(derived_passes(snap, request, images))
    if request.cryptomatte:
        out.update(samples.passes(request))
    return out


def cryptomatte_metadata(snap, request, material_names):
    """The render result's Cryptomatte metadata (key -> value) of the requested layers."""
    names = cryptomatte_names(snap, material_names)
    out = {}
    for kind in request.cryptomatte:
        out.update(cryptomatte.metadata(request.view_layer, kind, names[kind]))
    return out
