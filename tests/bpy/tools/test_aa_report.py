"""The anti-aliasing report: ``./dev aa-report --quick``, in-process.

The numbers must land in the JSON and between the markdown markers with the prose kept,
the stair-step error must fall with FXAA and with render samples, and the picture must
hold the three magnified crops side by side."""
import json

import pytest

from csm_tools import aa_report
from csm_tools.report_io import read_png

PROSE = "# Image quality\n\nHand-written prose.\n\n"


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("aa")
    page = out / "image-quality.md"
    page.write_text(PROSE + aa_report.BEGIN + "\nstale\n" + aa_report.END + "\nAfter.\n",
                    encoding="utf-8")
    numbers = out / "aa.json"
    assert aa_report.main(["--quick", "--out-dir", str(out), "--json", str(numbers)]) == 0
    with open(numbers, encoding="utf-8") as stream:
        return out, json.load(stream)


def test_anti_aliasing_straightens_the_edge(quick_run):
    _, rows = quick_run
    by_name = {row["setting"]: row for row in rows}
    assert set(by_name) == {"none", "FXAA", "4 samples"}
    aliased = by_name["none"]["stair_step_px"]
    assert 0.2 < aliased < 0.4                    # a hard edge: ~0.29 px of rounding
    assert by_name["FXAA"]["stair_step_px"] < 0.4 * aliased
    assert by_name["4 samples"]["stair_step_px"] < 0.5 * aliased
    assert all(row["slope"] == pytest.approx(0.1228, abs=0.01) for row in rows)
    assert all(row["wall_ms"] > 0 for row in rows)


def test_page_and_picture(quick_run):
    out, rows = quick_run
    text = (out / "image-quality.md").read_text(encoding="utf-8")
    assert text.startswith(PROSE) and text.endswith("\nAfter.\n")
    assert "stale" not in text and "| FXAA |" in text
    image = read_png(out / "images" / "antialiasing.png")
    assert image.shape[1] == 3 * image.shape[0] * (320 // 6) // (180 // 6)
    assert image[..., :3].std() > 10          # a picture, not a blank
