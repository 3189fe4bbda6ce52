"""The shadow-quality report: ``./dev quality-report --quick``, in-process.

Runs in-process on shadow_test at the quick size. The acne experiment's "none" point (all
biases 0, no front-face culling) must show more false shadow than the defaults, counted
in real pixels, and the numbers must land in the JSON and between the markdown markers.
"""
import json

import numpy as np
import pytest

from csm_tools import ground_truth, quality_report
from csm_tools.report_io import read_png

PROSE_BEFORE = "# Shadow acne\n\nHand-written prose that the tool must keep.\n\n"
PROSE_AFTER = "\nMore prose after the tables.\n"


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("quality")
    markdown = out / "shadow-acne.md"
    markdown.write_text(PROSE_BEFORE + quality_report.BEGIN + "\nstale numbers\n"
                        + quality_report.END + PROSE_AFTER, encoding="utf-8")
    numbers = out / "points.json"
    assert quality_report.main(["--quick", "--out-dir", str(out),
                                "--json", str(numbers)]) == 0
    with open(numbers, encoding="utf-8") as stream:
        report = json.load(stream)
    return out, report


def _point(report, technique):
    matches = [p for p in report["points"]
               if p["group"] == "acne" and p["technique"] == technique]
    assert len(matches) == 1
    return matches[0]


def test_json_holds_every_point(quick_run):
    _, report = quick_run
    assert report["scenes"] == ["shadow_test"]
    assert len(report["points"]) >= 3
    none, defaults = _point(report, "none"), _point(report, "defaults")
    assert none["settings"] == {"depth_bias": 0.0, "slope_bias": 0.0, "normal_offset": 0.0,
                                "cull_front_faces": False}
    assert defaults["settings"] == {}
    for point in report["points"]:
        result = point["result"]
        # A comparison of nothing would pass trivially.
        assert result["compared_pixels"] > 0.3 * result["width"] * result["height"]
        assert result["mismatch_percent"] == pytest.approx(
            result["false_shadow_percent"] + result["missed_shadow_percent"])


def test_no_bias_shows_more_false_shadow_than_defaults(quick_run):
    out, report = quick_run
    none, defaults = _point(report, "none")["result"], _point(report, "defaults")["result"]
    assert none["false_shadow_pixels"] > 100
    assert none["false_shadow_percent"] > 10 * max(defaults["false_shadow_percent"], 0.1)
    # The heat maps show the same pixels: red = false shadow.
    heat = read_png(out / "images" / "acne_none.png")
    red = np.all(heat == np.array(ground_truth.COLOR_FALSE_SHADOW, np.uint8), axis=2).sum()
    assert red == none["false_shadow_pixels"]
    heat = read_png(out / "images" / "acne_defaults.png")
    red = np.all(heat == np.array(ground_truth.COLOR_FALSE_SHADOW, np.uint8), axis=2).sum()
    assert red == defaults["false_shadow_pixels"]


def test_markdown_section_is_rewritten_and_prose_kept(quick_run):
    out, report = quick_run
    text = (out / "shadow-acne.md").read_text(encoding="utf-8")
    assert text.startswith(PROSE_BEFORE + quality_report.BEGIN)
    assert text.endswith(quality_report.END + PROSE_AFTER)
    assert "stale numbers" not in text
    none = _point(report, "none")["result"]
    assert f"{none['false_shadow_percent']:.3f}" in text
    assert "images/acne_none.png" in text


def _sweep_point(report, setting, value):
    matches = [p for p in report["points"] if p["group"] == "sweep"
               and p["setting"] == setting and p["value"] == value]
    assert len(matches) == 1
    return matches[0]["result"]


def test_sharpen_sweep_shows_the_faint_shadow_on_lit_ground(quick_run):
    """PCF Sharpen moves no pixel across half lit, so mismatch cannot show it; the fully
    lit figures must: the 3x3 kernel's spill onto lit ground at Sharpen 1 is mostly gone
    at 16, counted in real pixels, and the report's lit-ground table shows both."""
    out, report = quick_run
    plain, sharp = (_sweep_point(report, "pcf_sharpen", 1.0),
                    _sweep_point(report, "pcf_sharpen", 16.0))
    assert abs(sharp["mismatch_percent"] - plain["mismatch_percent"]) < 0.05
    assert plain["partial_on_lit_pixels"] > 20
    assert sharp["partial_on_lit_pixels"] < 0.5 * plain["partial_on_lit_pixels"]
    text = (out / "shadow-acne.md").read_text(encoding="utf-8")
    assert "Fully lit pixels" in text
    assert f"| 1 | {plain['partial_on_lit_percent']:.2f} / " in text
    assert f"| 16 | {sharp['partial_on_lit_percent']:.2f} / " in text
