"""One frame's plain data: camera, lights, settings, mesh instances.

Owns the ``FrameSnapshot`` that ``blender/snapshot.py`` fills once per frame and every later
stage reads; nothing here knows about Blender. numpy only.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from .camera import CameraView
from .settings_model import Settings


@dataclass
class Sun:
    to_light: np.ndarray        # unit vector pointing towards the sun
    color: np.ndarray           # W/m^2 on a surface facing the sun (colour x strength)
    casts_shadow: bool
    name: str = ""
    angle: float = 0.0          # angular diameter (radians): soft shadows' penumbra


@dataclass
class PointLight:
    position: np.ndarray
    color: np.ndarray           # see falloff: W/sr (PHYSICAL) or W/m^2 at the light
    radius: float               # where the light ends (scene units)
    falloff: str = "PHYSICAL"   # frame_layout.LIGHT_FALLOFFS
    casts_shadow: bool = False  # Blender's Shadow checkbox (course lights: off)
    clip_start: float = 0.05    # shadow maps begin this far from the light (scene units)
    source_radius: float = 0.0  # Blender's Radius (scene units): soft shadows' penumbra


@dataclass
class SpotLight:
    position: np.ndarray
    direction: np.ndarray       # unit vector the light shines along
    color: np.ndarray
    radius: float
    spot_size: float            # full cone angle, radians
    spot_blend: float
    casts_shadow: bool
    world_from_light: np.ndarray
    clip_start: float
    falloff: str = "PHYSICAL"   # frame_layout.LIGHT_FALLOFFS, as for PointLight
    source_radius: float = 0.0  # Blender's Radius (scene units): soft shadows' penumbra


# Blender's default Shadow Terminator Geometry Offset (Object > Shading).
DEFAULT_TERMINATOR_OFFSET = 0.1


@dataclass
class MeshInstance:
    key: str                    # mesh-cache key (the original object's name)
    world_from_object: np.ndarray
    visible_camera: bool = True     # Object > Visibility > Ray Visibility > Camera
    casts_shadow: bool = True       # Object > Visibility > Ray Visibility > Shadow
    # Object > Shading > Shadow Terminator > Geometry Offset
    terminator_offset: float = DEFAULT_TERMINATOR_OFFSET
    name: str = ""                  # the object's name (Cryptomatte Object)
    asset: str = ""                 # its topmost parent's name (Cryptomatte Asset)


@dataclass
class FrameSnapshot:
    camera: CameraView
    settings: Settings
    sun: Sun = None
    points: list = field(default_factory=list)
    spots: list = field(default_factory=list)
    instances: list = field(default_factory=list)
    mesh_sources: dict = field(default_factory=dict)   # key -> evaluated object
    ambient: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # The World's radiance as spherical harmonics (core/world_light.py), times Ambient
    # Strength as ``ambient``; None: the uniform ``ambient``.
    world_sh: np.ndarray = None
    background: np.ndarray = field(default_factory=lambda: np.zeros(3))
    film_transparent: bool = False
    pixel_filter_width: float = 1.5    # Film > Filter Size (pixels): final-render AA spread
    sample_index: int = 0       # jittered sample of a final render (0: the first, unjittered)
    is_viewport: bool = False   # a viewport frame (one of a continuous stream) or a render
    frame: int = 0              # the scene's frame number (Timeline > Current Frame)
    scene_name: str = ""
    warnings: list = field(default_factory=list)      # what the snapshot had to correct



def spot_cone_cosines(spot):
    """cos of the outer cone half-angle, and the cosine where Blender's spot_blend
    softening ends: Cycles and EEVEE blend linearly in the cosine, over spot_blend of the
    way from the cone's edge to its axis."""
    half = 0.5 * spot.spot_size
    cos_outer = math.cos(half)
    cos_inner = cos_outer + (1.0 - cos_outer) * min(max(spot.spot_blend, 0.0), 1.0)
    return cos_outer, max(cos_inner, cos_outer + 1e-4)
