"""The one camera model every stage shares.

Owns ``CameraProjection`` (a camera's OpenGL projection as lens values: perspective or
orthographic, field of view, aspect, shift, clip range; built from Blender's numbers or
decoded from any OpenGL ``clip_from_view``), ``CameraView`` (where the camera is, its
projection and the image size in pixels, as one frame sees it) and ``world_positions``
(pixel centres back to world space, as the lighting pass does). The clip range is decoded
from a projection matrix in exactly one place, ``CameraProjection.from_clip_from_view``.
numpy only.
"""

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .checks import finite, matrix4
from .matrices import inverse_projection, inverse_rigid


# Widest far / near ratio a perspective camera is drawn with (see from_clip_from_view).
MAX_CLIP_RATIO = 1e7


@dataclass(frozen=True)
class CameraProjection:
    """A camera's projection, enough to build the same OpenGL matrix the G-buffer uses.

    - ``kind``: ``'PERSP'`` or ``'ORTHO'``.
    - ``fov_y``: full vertical field of view in radians (``'PERSP'``).
    - ``ortho_height``: full height of the view in scene units (``'ORTHO'``).
    - ``aspect``: width / height of the image (pixel aspect included).
    - ``shift_x``, ``shift_y``: Blender lens shift, in units of the *larger* image
      dimension (Blender's 'Auto' sensor fit): shift_x = 1 moves the view window by one
      full width of a landscape image.
    - ``clip_start``, ``clip_end``: view depths (scene units) of the near and far clip.
    """

    kind: str = "PERSP"
    fov_y: float = math.radians(39.6)
    ortho_height: float = 6.0
    aspect: float = 16.0 / 9.0
    shift_x: float = 0.0
    shift_y: float = 0.0
    clip_start: float = 0.1
    clip_end: float = 100.0

    def __post_init__(self):
        if self.kind not in ("PERSP", "ORTHO"):
            raise ValueError(f"camera projection kind must be 'PERSP' or 'ORTHO', "
                             f"got {self.kind!r}")
        for name in ("fov_y", "ortho_height", "aspect", "shift_x", "shift_y",
                     "clip_start", "clip_end"):
            finite(f"camera {name}", getattr(self, name))
        if self.kind == "PERSP" and not 0.0 < self.fov_y < math.pi:
            raise ValueError(f"camera fov_y must be between 0 and pi radians, got {self.fov_y}")
        if self.kind == "ORTHO" and not self.ortho_height > 0.0:
            raise ValueError(f"camera ortho_height must be above 0, got {self.ortho_height}")
        if not self.aspect > 0.0:
            raise ValueError(f"camera aspect must be above 0, got {self.aspect}")
        if self.kind == "PERSP" and not self.clip_start > 0.0:
            raise ValueError(f"perspective camera clip_start must be above 0, "
                             f"got {self.clip_start}")
        if not self.clip_end > self.clip_start:
            raise ValueError(f"camera clip_end ({self.clip_end}) must be greater than "
                             f"clip_start ({self.clip_start})")

    @property
    def is_perspective(self):
        return self.kind == "PERSP"

    def view_window(self):
        """(left, right, bottom, top) of the view window: at view depth 1 for a perspective
        camera (tangents of the half angles), in scene units for an orthographic one."""
        half_h = math.tan(0.5 * self.fov_y) if self.is_perspective else 0.5 * self.ortho_height
        half_w = half_h * self.aspect
        # Blender measures shift in the larger image dimension (full size = 2 * larger half).
        larger = 2.0 * max(half_w, half_h)
        centre_x, centre_y = self.shift_x * larger, self.shift_y * larger
        return (centre_x - half_w, centre_x + half_w, centre_y - half_h, centre_y + half_h)

    def clip_from_view(self):
        """OpenGL projection (glFrustum / glOrtho), lens shift included, z mapped to -1..1."""
        left, right, bottom, top = self.view_window()
        near, far = self.clip_start, self.clip_end
        m = np.zeros((4, 4))
        m[0, 0] = 2.0 / (right - left)
        m[1, 1] = 2.0 / (top - bottom)
        if self.is_perspective:
            # Window given at depth 1, so glFrustum's 2n/(r-l) becomes 2/(R-L).
            m[0, 2] = (right + left) / (right - left)
            m[1, 2] = (top + bottom) / (top - bottom)
            m[2, 2] = -(far + near) / (far - near)
            m[2, 3] = -2.0 * far * near / (far - near)
            m[3, 2] = -1.0
        else:
            m[0, 3] = -(right + left) / (right - left)
            m[1, 3] = -(top + bottom) / (top - bottom)
            m[2, 2] = -2.0 / (far - near)
            m[2, 3] = -(far + near) / (far - near)
            m[3, 3] = 1.0
        return m

    @classmethod
    def from_clip_from_view(cls, clip_from_view, clip_start=None, clip_end=None):
        """Recover the projection from an OpenGL matrix (e.g. Blender's
        ``calc_matrix_camera`` or a viewport's ``window_matrix``). ``clip_start`` and
        ``clip_end``, when known exactly, replace the values decoded from the matrix.

        NOTE: a float32 perspective matrix cannot hold a far plane more than ~10^7 times the
        near one (its z row rounds to -1 and far decodes as infinite); such a far plane is
        taken as ``MAX_CLIP_RATIO`` x near, which is as far as the depth math can reach."""
        m = matrix4("clip_from_view", clip_from_view)
        if abs(m[3, 2] + 1.0) < 1e-9 and abs(m[3, 3]) < 1e-9:
            kind = "PERSP"
            width, height = 2.0 / m[0, 0], 2.0 / m[1, 1]
            centre_x, centre_y = m[0, 2] * width * 0.5, m[1, 2] * height * 0.5
            # A far plane float32 cannot hold divides by zero here (see the NOTE above).
            with np.errstate(divide="ignore", invalid="ignore"):
                near, far = m[2, 3] / (m[2, 2] - 1.0), m[2, 3] / (m[2, 2] + 1.0)
        elif np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9):
            kind = "ORTHO"
            width, height = 2.0 / m[0, 0], 2.0 / m[1, 1]
            centre_x, centre_y = -m[0, 3] * width * 0.5, -m[1, 3] * height * 0.5
            near, far = (m[2, 3] + 1.0) / m[2, 2], (m[2, 3] - 1.0) / m[2, 2]
        else:
            raise ValueError(f"clip_from_view is neither an OpenGL perspective nor an "
                             f"orthographic projection (bottom row {m[3].tolist()})")
        if kind == "PERSP" and math.isfinite(near) and near > 0.0 and \
                not (math.isfinite(far) and near < far <= near * MAX_CLIP_RATIO):
            far = near * MAX_CLIP_RATIO
        if clip_start is not None:
            near = clip_start
        if clip_end is not None:
            far = clip_end
        if not (width > 0.0 and height > 0.0):
            raise ValueError(f"clip_from_view has a mirrored or empty view window "
                             f"(width {width}, height {height})")
        larger = max(width, height)
        return cls(kind=kind,
                   fov_y=2.0 * math.atan(0.5 * height) if kind == "PERSP" else cls.fov_y,
                   ortho_height=height if kind == "ORTHO" else cls.ortho_height,
                   aspect=width / height, shift_x=centre_x / larger, shift_y=centre_y / larger,
                   clip_start=float(near), clip_end=float(far))


def _as_projection(projection):
    if isinstance(projection, CameraProjection):
        return projection
    return CameraProjection.from_clip_from_view(projection)


def as_projection(projection):
    """A ``CameraProjection`` from itself or from an OpenGL ``clip_from_view`` matrix."""
    if isinstance(projection, CameraProjection):
        return projection
    return CameraProjection.from_clip_from_view(projection)


@dataclass
class CameraView:
    """One frame's camera: ``world_from_view`` (OpenGL view axes: -Z forward, +Y up),
    the OpenGL ``clip_from_view`` the G-buffer uses, and the image size in pixels. The clip
    range comes from the projection unless the camera's own exact values are given."""
    world_from_view: np.ndarray
    clip_from_view: np.ndarray
    width: int
    height: int
    clip_start: float = None
    clip_end: float = None

    def __post_init__(self):
        if self.clip_start is None or self.clip_end is None:
            decoded = CameraProjection.from_clip_from_view(self.clip_from_view)
            self.clip_start = decoded.clip_start if self.clip_start is None else self.clip_start
            self.clip_end = decoded.clip_end if self.clip_end is None else self.clip_end
        self.clip_start, self.clip_end = float(self.clip_start), float(self.clip_end)

    @cached_property
    def projection(self):
        """The lens, with this camera's exact clip range."""
        return CameraProjection.from_clip_from_view(self.clip_from_view, self.clip_start,
                                                    self.clip_end)

    @property
    def is_perspective(self):
        # NOTE: read from the matrix's bottom row, not via ``projection``, so a degenerate
        # lens (which from_clip_from_view refuses) still says what kind of camera it is.
        return abs(float(self.clip_from_view[3, 3])) < 0.5

    @property
    def position(self):
        return self.world_from_view[:3, 3].copy()

    @property
    def forward(self):
        f = -self.world_from_view[:3, 2]
        return f / np.linalg.norm(f)

    @property
    def view_from_world(self):
        return inverse_rigid(self.world_from_view)

    @property
    def clip_from_world(self):
        return self.clip_from_view @ self.view_from_world

    @property
    def world_from_clip(self):
        return np.asarray(self.world_from_view, dtype=np.float64) @ \
            inverse_projection(self.clip_from_view)


def world_positions(camera, view_depth):
    """(H, W, 3) world positions of pixel centres at the given view depths, in float64:
    the point at that depth on each pixel's ray (``world_position_at`` in
    shaders/surface.glsl finds the same point between the near and far planes; this takes
    the ray from the camera or, orthographic, along the view, so a far plane too far for
    the matrix to hold changes nothing)."""
    height, width = view_depth.shape
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = (np.arange(height) + 0.5) / height * 2.0 - 1.0
    ndc = np.stack(np.broadcast_arrays(x[None, :], y[:, None]), axis=-1)     # (H, W, 2)
    world_from_clip = np.linalg.inv(camera.clip_from_world)
    clip = np.concatenate([ndc, np.full(ndc.shape[:2] + (1,), -1.0),
                           np.ones(ndc.shape[:2] + (1,))], axis=-1)
    world = clip @ world_from_clip.T
    near_points = world[..., :3] / world[..., 3:]
    position = np.asarray(camera.position, dtype=np.float64)
    forward = np.asarray(camera.forward, dtype=np.float64)
    if camera.is_perspective:
        ray = near_points - position
        return position + ray * (view_depth / (ray @ forward))[..., None]
    near_depth = (near_points - position) @ forward
    return near_points + forward * (view_depth - near_depth)[..., None]
