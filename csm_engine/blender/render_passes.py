"""The render passes as Blender sees them: which the View Layer asks for, their registration
with Blender, and writing them (and Cryptomatte's metadata) into the render result.

Owns ``PASSES`` (each pass EEVEE shows in View Layer > Passes that CSM draws: the
``ViewLayer`` property that enables it, its channels, channel letters and kind),
``request`` (the View Layer's and World's settings -> ``render.passes.PassRequest``),
``register`` (``RenderEngine.update_render_passes``: the compositor's Render Layers node
shows exactly these sockets) and ``write``. The names are Blender 5.0's; ``compat`` gives
each host's. Shadow and Cascade are always written (CSM's own).
"""

from typing import NamedTuple

from ..core import cryptomatte
from ..render.passes import Mist, PassRequest
from . import compat


class PassSpec(NamedTuple):
    name: str               # Blender 5.0's name (render/passes.py uses it too)
    enabled_by: str         # the ViewLayer property that turns it on
    channels: int
    chan_id: str
    kind: str               # 'COLOR', 'VECTOR' or 'VALUE'


PASSES = (
    PassSpec("Depth", "use_pass_z", 1, "Z", 'VALUE'),
    PassSpec("Mist", "use_pass_mist", 1, "Z", 'VALUE'),
    PassSpec("Normal", "use_pass_normal", 3, "XYZ", 'VECTOR'),
    PassSpec("Position", "use_pass_position", 3, "XYZ", 'VECTOR'),
    PassSpec("Diffuse Direct", "use_pass_diffuse_direct", 3, "RGB", 'COLOR'),
    PassSpec("Diffuse Color", "use_pass_diffuse_color", 3, "RGB", 'COLOR'),
    PassSpec("Glossy Direct", "use_pass_glossy_direct", 3, "RGB", 'COLOR'),
    PassSpec("Glossy Color", "use_pass_glossy_color", 3, "RGB", 'COLOR'),
    PassSpec("Emission", "use_pass_emit", 3, "RGB", 'COLOR'),
    PassSpec("Environment", "use_pass_environment", 3, "RGB", 'COLOR'),
    PassSpec("Ambient Occlusion", "use_pass_ambient_occlusion", 3, "RGB", 'COLOR'),
)
# CSM's own passes, always written: sun visibility and the cascade read.
ALWAYS = (PassSpec("Shadow", "", 1, "X", 'VALUE'), PassSpec("Cascade", "", 1, "X", 'VALUE'))
CRYPTOMATTE_SETTINGS = (("OBJECT", "use_pass_cryptomatte_object"),
                        ("MATERIAL", "use_pass_cryptomatte_material"),
                        ("ASSET", "use_pass_cryptomatte_asset"))


def request(view_layer, world=None):
    """The passes ``view_layer`` enables (``PassRequest``), with ``world``'s mist."""
    names = frozenset(spec.name for spec in PASSES
                      if getattr(view_layer, spec.enabled_by, False))
    kinds = tuple(kind for kind, setting in CRYPTOMATTE_SETTINGS
                  if getattr(view_layer, setting, False))
    mist = Mist()
    settings = getattr(world, "mist_settings", None) if world is not None else None
    if settings is not None:
        mist = Mist(float(settings.start), float(settings.depth), str(settings.falloff))
    return PassRequest(names=names, cryptomatte=kinds,
                       cryptomatte_levels=int(getattr(view_layer, "pass_cryptomatte_depth", 6)),
                       mist=mist, view_layer=view_layer.name)


def _specs(wanted):
    """(host pass name, PassSpec) of every pass ``wanted`` (a PassRequest) writes."""
    specs = [spec for spec in PASSES if spec.name in wanted.names] + list(ALWAYS)
    for kind in wanted.cryptomatte:
        for index in range(cryptomatte.pass_count(wanted.cryptomatte_levels)):
            name = f"{cryptomatte.LAYER_PASS_NAMES[kind]}{index:02d}"
            specs.append(PassSpec(name, "", 4, "RGBA", 'COLOR'))
    return [(compat.render_pass_name(spec.name), spec) for spec in specs]


def register(engine, scene, view_layer):
    """``update_render_passes``: register Combined and every pass the layer enables."""
    engine.register_pass(scene, view_layer, "Combined", 4, "RGBA", 'COLOR')
    for name, spec in _specs(request(view_layer)):
        engine.register_pass(scene, view_layer, name, spec.channels, spec.chan_id, spec.kind)


def _fit_channels(pixels, channels):
    """``pixels`` (H, W, C) with ``channels`` channels: a one-channel image repeated (AO
    as grey), extra channels dropped."""
    if pixels.shape[-1] == channels:
        return pixels
    if pixels.shape[-1] == 1:
        return pixels.repeat(channels, axis=-1)
    return pixels[..., :channels]


def write(engine, render_result, images, wanted, metadata, memory=None):
    """Write ``images`` (pass name -> (H, W, C), already cut to the result's region) into
    ``render_result``'s first layer for every pass ``wanted`` writes, and ``metadata``
    into the render's stamp data. A pass Blender did not allocate is added where Blender
    allows. ``memory`` (``render.readback.ReadbackMemory``): where a channel or region
    of an image is made contiguous for Blender, kept between renders."""
    passes = render_result.layers[0].passes
    for name, spec in _specs(wanted):
        pixels = images.get(spec.name)
        if pixels is None:
            continue
        render_pass = passes.find_by_name(name, "")
        if render_pass is None:
            try:
                engine.add_pass(name, spec.channels, spec.chan_id)
            except Exception:       # a render result that takes no more passes
                continue
            passes = render_result.layers[0].passes
            render_pass = passes.find_by_name(name, "")
            if render_pass is None:
                continue
        pixels = _fit_channels(pixels, render_pass.channels)
        if memory is not None:
            pixels = memory.contiguous(name, pixels)
        compat.write_pass(render_pass, pixels)
    # NOTE: the stamp data of the render itself (get_result, as Cycles writes its
    # Cryptomatte metadata): ``begin_result``'s result is merged into it by its pixels
    # alone, so fields added there never reach the image or a file.
    full_result = engine.get_result() if metadata else None
    for key, value in metadata.items():
        (full_result or render_result).stamp_data_add_field(key, value)
