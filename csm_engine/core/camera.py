"""The camera model every stage shares: a view matrix, an OpenGL projection, clip range
and pixel size.

numpy only.
"""

from dataclasses import dataclass

import numpy as np


@dataclass
class CameraView:
    world_from_view: np.ndarray
    clip_from_view: np.ndarray
    is_perspective: bool
    clip_start: float
    clip_end: float
    width: int
    height: int

    @property
    def position(self):
        return self.world_from_view[:3, 3].copy()

    @property
    def forward(self):
        f = -self.world_from_view[:3, 2]
        return f / np.linalg.norm(f)

    @property
    def clip_from_world(self):
        return self.clip_from_view @ np.linalg.inv(self.world_from_view)



def clip_range_from_projection(clip_from_view, is_perspective):
    """Near and far clip distances encoded in an OpenGL projection matrix."""
    a, b = clip_from_view[2, 2], clip_from_view[2, 3]
    if is_perspective:
        return b / (a - 1.0), b / (a + 1.0)
    return (b + 1.0) / a, (b - 1.0) / a

