"""What one view's shadow planning remembers from one frame to the next.

Owns ``ShadowViewState``. The engine keeps one per view (each viewport, and the final
render) and hands it to ``shadow_plan.plan_shadows``; two views of one scene never see each
other's frozen cascades or hysteresis. Everything else in ``core`` is a function of its
arguments (memos of pure functions aside, see ``memo.py``). Plain data, numpy only.
"""

from dataclasses import dataclass

from .camera import CameraView
from .cascades import CascadeSet, ReceiverTermsCache


@dataclass(frozen=True, eq=False)
class FrozenCascades:
    """The cascades Freeze Cascades holds, and the camera they were fitted for (the
    overlay draws their boxes as seen from the moving camera)."""
    cascades: CascadeSet
    camera: CameraView


class ShadowViewState:
    """One view's shadow-planning state, carried from frame to frame.

    - ``frozen``: ``FrozenCascades`` while Freeze Cascades is on, else None.
    - ``fitted_depth_range`` (viewports): the visible depth range the cascades were last
      fitted to (Fit to Visible Depth), held while the new one still fits
      (``cascades.visible_depth_range``), so the splits do not pop while the view moves.
    - ``held_cascades`` (viewports): the last frame's ``CascadeFit`` per cascade, each
      kept while it still holds its receivers (``cascades.holding``): a view that moves a
      little keeps its shadow maps. A final render keeps neither: its frames depend on
      nothing but their own inputs, so any process (a farm's workers, ``-a``) renders
      each frame to the same pixels; its boxes are quantized instead
      (``cascades.quantizing``), which keeps them over small camera moves too.
    - ``receiver_cache``: the per-block terms of the last fit
      (``cascades.ReceiverTermsCache``), kept while the blocks and the camera stay.

    A view that switches to another scene starts afresh (``follow_scene``).
    """

    def __init__(self, scene_name=None):
        self.scene_name = scene_name
        self.frozen = None
        self.fitted_depth_range = None
        self.held_cascades = None
        self.receiver_cache = ReceiverTermsCache()

    def follow_scene(self, scene_name):
        """Forget everything fitted for another scene than ``scene_name``: a view that
        shows another scene must not draw with the first one's cascades."""
        if scene_name != self.scene_name:
            self.__init__(scene_name)
