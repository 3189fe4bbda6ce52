"""The CSM viewport in a real Blender window: Debian's Blender 3.4 under Xvfb.

Owns the GUI viewport acceptance test: a 3D viewport switched to CSM rendered mode,
looking through the scene camera, shows the default scene as CSM renders it with F12.
``gui_driver.py`` runs inside Blender and writes a full-window screenshot, the camera
frame's rectangle in that screenshot and the F12 renders; this file starts the X server
and Blender, then compares pixels.

``CSM_UPDATE_DOCS=1`` also copies the screenshot, once it has matched the render, to
``docs/images/viewport_blender34.png``.
"""

import os
import shutil

import numpy as np
import pytest

pytestmark = [pytest.mark.gui, pytest.mark.slow]

from tests.conftest import REPO
from tests.hosts.gui_host import (  # noqa: F401 (x_display: a fixture used by name)
    SCREEN_SIZE, blender_env, load_png, run_driver, save_preferences_without_splash,
    x_display)

DRIVER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "gui_driver.py")
DOCS_SCREENSHOT = os.path.join(REPO, "docs", "images", "viewport_blender34.png")
BLENDER_TIMEOUT_S = 120

# How close the viewport's camera frame must be to the F12 render (RGB in 0..1).
# Measured here (the same on every run): mean 0.0022, and 0.5% of pixels off by more than
# 0.1. Both images come from the same pipeline through the same view transform, with dither
# off; they differ only where rasterization does: the frame sits at a fractional window
# position, so polygon edges land on other pixels; the frame is resampled bilinearly;
# Blender draws the camera frame's outline even with overlays off; and the viewport's
# cascades are fitted to the whole region rather than the frame, which moves shadow edges
# by a texel. For scale: the render shifted by 1 / 2 / 4 px gives 1.0% / 1.8% / 3.3% of
# pixels off; without sun shadows, mean 0.014 and 8.8%; flipped left-right 0.08 and 43%.
MAX_MEAN_DIFFERENCE = 0.01
PIXEL_OFF = 0.1               # a pixel is "off" when a channel differs by more than this
MAX_FRACTION_OFF = 0.02

# What the frame must show for the match to mean something (luminance 0..1).
SHADOW_STEP = 0.05            # darker than the shadowless render by this much: in shadow
SUNLIT_TOLERANCE = 0.02       # as bright as the shadowless render: in sunlight
LIT = 0.15


class ViewportRun:
    """What the driver recorded: paths of its images and its JSON report."""

    def __init__(self, out_dir, report, output, seconds):
        self.out_dir = out_dir
        self.report = report
        self.output = output
        self.seconds = seconds

    def path(self, name):
        return os.path.join(self.out_dir, name)


@pytest.fixture(scope="module")
def viewport_run(x_display, hosts, tmp_path_factory):
    """Blender 3.4's window with the default scene in CSM rendered mode, captured once."""
    blender = hosts.blender_binary()
    root = tmp_path_factory.mktemp("gui_viewport")
    out_dir = root / "out"
    out_dir.mkdir()
    env = blender_env(hosts, root, x_display)
    save_preferences_without_splash(blender, env, str(root))

    report, output, seconds = run_driver(blender, DRIVER, [out_dir], env, root,
                                         "viewport.json", BLENDER_TIMEOUT_S)
    return ViewportRun(str(out_dir), report, output, seconds)


# --- pixels -------------------------------------------------------------------------------

def camera_frame_crop(window_image, frame, size):
    """Sample ``window_image`` inside ``frame`` (window pixels, bottom-left origin, edges as
    continuous coordinates) at the pixel centres of a ``size`` = (width, height) image:
    the viewport's camera view resampled onto the render's pixel grid (bilinear)."""
    width, height = size
    window_height = window_image.shape[0]
    x = frame["x_min"] + (np.arange(width) + 0.5) * (frame["x_max"] - frame["x_min"]) / width
    y = frame["y_max"] - (np.arange(height) + 0.5) * (frame["y_max"] - frame["y_min"]) / height
    # Continuous coordinates -> array indices whose integer values are pixel centres.
    rows = (window_height - y) - 0.5
    cols = x - 0.5
    row0 = np.clip(np.floor(rows).astype(int), 0, window_image.shape[0] - 2)
    col0 = np.clip(np.floor(cols).astype(int), 0, window_image.shape[1] - 2)
    fr = np.clip(rows - row0, 0.0, 1.0)[:, None, None]
    fc = np.clip(cols - col0, 0.0, 1.0)[None, :, None]
    top = window_image[row0][:, col0] * (1 - fc) + window_image[row0][:, col0 + 1] * fc
    bottom = window_image[row0 + 1][:, col0] * (1 - fc) + window_image[row0 + 1][:, col0 + 1] * fc
    return top * (1 - fr) + bottom * fr


def difference(a, b):
    """Mean absolute RGB difference and the fraction of pixels off by more than PIXEL_OFF."""
    assert a.shape == b.shape, (a.shape, b.shape)
    delta = np.abs(a.astype(np.float64) - b.astype(np.float64))
    return float(delta.mean()), float((delta.max(axis=-1) > PIXEL_OFF).mean())


def matches(a, b):
    mean, fraction_off = difference(a, b)
    return mean <= MAX_MEAN_DIFFERENCE and fraction_off <= MAX_FRACTION_OFF


def luminance(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(scope="module")
def images(viewport_run):
    render = load_png(viewport_run.path("render.png"))
    window = load_png(viewport_run.path("viewport.png"))
    height, width = render.shape[:2]
    crop = camera_frame_crop(window, viewport_run.report["camera_frame"], (width, height))
    return {"window": window, "render": render, "crop": crop,
            "render_no_shadows": load_png(viewport_run.path("render_no_shadows.png"))}


# --- tests --------------------------------------------------------------------------------

def test_driver_ran_the_csm_viewport_in_blender_3_4(viewport_run):
    report = viewport_run.report
    assert report["blender"].startswith("3.4"), f"expected Debian's Blender 3.4: {report['blender']}"
    assert report["window_size"] == list(SCREEN_SIZE), report["window_size"]
    assert report["viewport_draws"] >= 2, report
    assert report["mesh_uploads"] >= 1, report
    assert report["scene_file"].endswith(os.path.join("csm_engine", "data", "scenes", "default.json"))
    # Blender's full-window screenshot and the frame rectangle use the same pixels.
    window = load_png(viewport_run.path("viewport.png"))
    assert window.shape[:2] == (SCREEN_SIZE[1], SCREEN_SIZE[0]), window.shape


def test_viewport_shows_the_default_scene_as_csm_renders_it(viewport_run, images):
    crop, render = images["crop"], images["render"]
    mean, fraction_off = difference(crop, render)
    report = viewport_run.report
    detail = (f"mean difference {mean:.4f} (limit {MAX_MEAN_DIFFERENCE}), {fraction_off:.2%} "
              f"of pixels off by > {PIXEL_OFF} (limit {MAX_FRACTION_OFF:.0%}); camera frame "
              f"{report['camera_frame']}, render {report['render_size']}, images in "
              f"{viewport_run.out_dir}")
    assert mean <= MAX_MEAN_DIFFERENCE and fraction_off <= MAX_FRACTION_OFF, detail
    if os.environ.get("CSM_UPDATE_DOCS") == "1":
        # Only a screenshot that passed the comparison goes into the documentation.
        os.makedirs(os.path.dirname(DOCS_SCREENSHOT), exist_ok=True)
        shutil.copyfile(viewport_run.path("viewport.png"), DOCS_SCREENSHOT)


def test_viewport_picture_has_lit_and_shadowed_content(images):
    """A match between two flat or empty pictures would prove nothing: the camera frame must
    show the landscape with the sun's shadows on it. Shadowed and sunlit pixels are found
    by comparing the viewport with the render whose sun casts no shadow, so the check does
    not depend on the sky colour or the ambient level."""
    crop = images["crop"]
    light = luminance(crop)
    shadowless = luminance(images["render_no_shadows"])
    in_shadow = float((shadowless - light > SHADOW_STEP).mean())
    sunlit = float(((np.abs(shadowless - light) < SUNLIT_TOLERANCE) & (light > LIT)).mean())
    green = float((crop[..., 1] > crop[..., 0] + 0.05).mean())
    summary = (f"luminance std {light.std():.3f}, in shadow {in_shadow:.1%}, sunlit "
               f"{sunlit:.1%}, green {green:.1%}")
    # Measured: std 0.10, in shadow 11%, sunlit 83%, green 91% (grass and tree tops).
    assert light.std() > 0.05, "the viewport picture is nearly uniform: " + summary
    assert in_shadow > 0.03, "the viewport shows (almost) no sun shadows: " + summary
    assert sunlit > 0.3, "the viewport shows (almost) no sunlit surfaces: " + summary
    assert green > 0.3, "the viewport does not show the green landscape: " + summary


def test_comparison_rejects_pictures_that_are_not_the_render(images):
    """The check above can fail: the same comparison rejects the render flipped upside down,
    the viewport shifted by a few pixels, and the same frame rendered without shadows."""
    crop, render = images["crop"], images["render"]
    controls = {
        "render flipped upside down": render[::-1],
        "render flipped left-right": render[:, ::-1],
        "render shifted 4 px right": np.roll(render, 4, axis=1),
        "render without sun shadows": images["render_no_shadows"],
    }
    accepted = {name: difference(crop, image) for name, image in controls.items()
                if matches(crop, image)}
    assert not accepted, f"the comparison accepted pictures that differ: {accepted}"


def test_an_objects_terminator_offset_edit_redraws_the_viewport(viewport_run):
    """Blender 3.4 keeps the Shadow Terminator Geometry Offset on the Cycles add-on's
    ``object.cycles``. After the driver adds a 12-segment smooth sphere (offset 0.1) and then
    edits the offset to 0 as CSM's Object panel does (gui_driver.set_terminator_offset; no
    redraw asked for), the viewport draws again by itself, and that draw shows the sphere's
    terminator band self-shadowed: the sphere darker, the rest of the frame unchanged."""
    edit = viewport_run.report.get("terminator_edit")
    assert edit and edit["draws_after_edit"] >= 1, viewport_run.report
    frame = viewport_run.report["camera_frame"]
    size = tuple(viewport_run.report["render_size"])
    before, after = (luminance(camera_frame_crop(load_png(viewport_run.path(name)), frame,
                                                 size))
                     for name in ("terminator_0.1.png", "terminator_0.png"))
    darker = before - after > SHADOW_STEP
    lighter = after - before > SHADOW_STEP
    height, width = darker.shape
    rows, cols = np.nonzero(darker)
    summary = (f"{int(darker.sum())} pixels darker, {int(lighter.sum())} lighter of "
               f"{width}x{height}; redraw {edit['seconds_to_redraw']} s after the edit")
    assert darker.sum() > 0.002 * darker.size, "the edit did not show: " + summary
    assert lighter.sum() < 0.1 * darker.sum(), summary
    # The sphere sits on the camera's axis: the change is in the middle of the frame.
    assert abs(cols.mean() / width - 0.5) < 0.2 and abs(rows.mean() / height - 0.5) < 0.2, \
        summary
    print(summary)
