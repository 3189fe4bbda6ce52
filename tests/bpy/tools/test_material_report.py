"""The material side-by-side: ``./dev material-report --quick``, in-process.

The three engines' pictures must be written and show the same scene (a lit, emissive,
textured picture, not a blank one), and the table showing them side by side must land
between the markers with the prose around it kept.
"""
import numpy as np

from csm_tools import material_report
from csm_tools.report_io import read_png

PROSE = "# Materials\n\nHand-written prose that the tool must keep.\n\n"


def test_quick_report_writes_three_pictures_and_the_table(tmp_path):
    page = tmp_path / "materials.md"
    page.write_text(PROSE + material_report.BEGIN + "\nstale\n" + material_report.END
                    + "\nAfter.\n", encoding="utf-8")
    assert material_report.main(["--quick", "--out-dir", str(tmp_path)]) == 0
    pictures = {engine: read_png(tmp_path / "images" / f"materials_{engine.lower()}.png")
                for engine in material_report.ENGINES}
    for engine, picture in pictures.items():
        assert picture.shape[:2] == (90, 160), engine
        assert picture[..., :3].std() > 10, f"{engine}'s picture is not blank"
    # The emissive cube is the brightest, warmest thing in every engine's picture.
    for engine, picture in pictures.items():
        rgb = picture[..., :3].astype(float)
        warm = (rgb[..., 0] > 240) & (rgb[..., 0] - rgb[..., 2] > 60)
        assert warm.sum() > 20, f"{engine} shows the emissive cube"
    # CSM and EEVEE agree on the whole picture to within a loose mean difference.
    difference = np.abs(pictures["CSM"][..., :3].astype(float) -
                        pictures["EEVEE"][..., :3].astype(float)).mean()
    assert difference < 40, difference
    text = page.read_text(encoding="utf-8")
    assert text.startswith(PROSE) and text.endswith("\nAfter.\n") and "stale" not in text
    assert "| CSM |" in text and "materials_cycles.png" in text
