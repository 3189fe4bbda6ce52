"""The ambient-occlusion report: ``./dev ao-report --quick``, in-process.

Runs the operator-built scene at the quick size. The numbers must land in the JSON and
between the markdown markers, the prose around them must stay, and the side-by-side image
must show the same comparison: its heat-map panel is black exactly where nothing was
compared and grey-to-coloured elsewhere. The EXR reader is checked on a file Blender wrote.
"""
import json

import numpy as np
import pytest

from csm_tools import ao_report
from csm_tools.report_io import read_png

PROSE_BEFORE = "# Ambient occlusion\n\nHand-written prose that the tool must keep.\n\n"
PROSE_AFTER = "\nMore prose after the tables.\n"


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ao")
    page = out / "ambient-occlusion.md"
    page.write_text(PROSE_BEFORE + ao_report.BEGIN + "\nstale numbers\n" + ao_report.END
                    + PROSE_AFTER, encoding="utf-8")
    numbers = out / "ao.json"
    assert ao_report.main(["--quick", "--out-dir", str(out), "--json", str(numbers)]) == 0
    with open(numbers, encoding="utf-8") as stream:
        return out, json.load(stream)


def test_json_holds_the_scene_and_a_small_error(quick_run):
    _, report = quick_run
    [result] = report["results"]
    assert result["scene"] == "blocks"
    assert result["compared_pixels"] > 0.4 * result["width"] * result["height"]
    # Both engines see occlusion (corners, contacts), and CSM is close to Cycles.
    assert result["cycles_mean"] < 0.97 and result["csm_mean"] < 0.97
    assert result["mean_abs_error"] < 0.08
    assert abs(result["bias"]) <= result["mean_abs_error"]


# CSM's AO changes from pixel to pixel at most this many times as much as Cycles' where
# Cycles' is smooth (quick run: measured 1.4; a one-slice search with a five-tap blur,
# visibly blotchy, 2.6; two slices with a 4x4 box, 1.6).
SMOOTHNESS_BOUND = 2.0


def test_csm_ao_is_as_smooth_as_cycles_where_cycles_is(quick_run):
    _, report = quick_run
    [result] = report["results"]
    csm, cycles = result["neighbour_difference_csm"], result["neighbour_difference_cycles"]
    print(f"neighbour difference: CSM {csm:.4f}, Cycles {cycles:.4f}")
    assert 0.0 < cycles and csm < SMOOTHNESS_BOUND * cycles


def test_neighbour_difference_sees_a_pattern_and_not_a_ramp_or_open_ground():
    rows, cols = np.mgrid[0:20, 0:30]
    cycles = 0.5 + 0.002 * cols                       # a gentle ramp, occluded
    compared = np.ones(cycles.shape, bool)
    csm, ref = ao_report.neighbour_difference(cycles.copy(), cycles, compared)
    assert csm == pytest.approx(ref) and ref == pytest.approx(0.001, abs=1e-4)
    checker = cycles + 0.02 * ((rows + cols) % 2)     # the same with a 2x2 pattern
    csm, ref = ao_report.neighbour_difference(checker, cycles, compared)
    assert csm == pytest.approx(0.02, abs=1e-3) and csm > 10 * ref
    # Open in Cycles (1 at both pixels) and steps Cycles shows too are left out.
    cycles_open = np.where(cols < 15, 1.0, cycles)
    cycles_open[:, 22:] -= 0.3
    csm_open = np.where(cols < 15, 1.0 - 0.1 * ((rows + cols) % 2), cycles_open)
    csm, ref = ao_report.neighbour_difference(csm_open, cycles_open, compared)
    assert csm == pytest.approx(ref)


def test_markdown_section_is_rewritten_and_prose_kept(quick_run):
    out, report = quick_run
    text = (out / "ambient-occlusion.md").read_text(encoding="utf-8")
    assert text.startswith(PROSE_BEFORE + ao_report.BEGIN)
    assert text.endswith(ao_report.END + PROSE_AFTER)
    assert "stale numbers" not in text
    assert f"{report['results'][0]['mean_abs_error']:.3f}" in text
    assert "images/ao_blocks.png" in text


def test_side_by_side_image_has_three_panels(quick_run):
    out, report = quick_run
    result = report["results"][0]
    image = read_png(out / "images" / "ao_blocks.png")
    width, height = result["width"], result["height"]
    assert image.shape == (height, 3 * width + 8, 3)
    heat = image[:, 2 * width + 8:].astype(int)
    compared = np.any(heat != 0, axis=2)
    assert compared.sum() == result["compared_pixels"]


def test_heatmap_colours_follow_the_sign_of_the_error():
    covered = np.ones((5, 5), bool)
    covered[0, 0] = False    # background: it and its neighbours are not compared
    cycles = np.full((5, 5), 0.5)
    csm = cycles.copy()
    csm[2, 1] = 0.1          # CSM darker
    csm[2, 3] = 0.9          # CSM lighter
    heat = ao_report.heatmap(csm, cycles, covered)
    assert tuple(heat[2, 2]) == tuple(ao_report.COLOR_AGREE.astype(np.uint8))
    assert tuple(heat[2, 1]) == tuple(ao_report.COLOR_CSM_DARKER.astype(np.uint8))
    assert tuple(heat[2, 3]) == tuple(ao_report.COLOR_CSM_LIGHTER.astype(np.uint8))
    assert tuple(heat[0, 0]) == (0, 0, 0) and tuple(heat[0, 1]) == (0, 0, 0)


def test_cycles_cache_reuses_a_render_of_the_same_scene_size_and_samples(tmp_path,
                                                                          monkeypatch):
    renders = []

    def fake_cycles_ao(scene, distance, samples, folder):
        renders.append((distance, samples))
        return np.full((2, 3), 0.25 * len(renders))
    monkeypatch.setattr(ao_report, "cycles_ao", fake_cycles_ao)
    cache = str(tmp_path / "cycles")
    first, seconds = ao_report.cached_cycles_ao(None, "blocks", 1.0, (3, 2), 16, cache)
    again, seconds_again = ao_report.cached_cycles_ao(None, "blocks", 1.0, (3, 2), 16, cache)
    assert renders == [(1.0, 16)]
    assert np.array_equal(first, again) and seconds_again == seconds
    more, _ = ao_report.cached_cycles_ao(None, "blocks", 1.0, (3, 2), 32, cache)
    assert renders == [(1.0, 16), (1.0, 32)] and not np.array_equal(more, first)
    ao_report.cached_cycles_ao(None, "blocks", 1.0, (3, 2), 16, None)   # no cache
    assert len(renders) == 3
