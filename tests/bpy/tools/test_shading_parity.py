"""The shading-parity tool: ``./dev shading-parity --quick SCENE``, in-process.

On one operator-made scene the tool must compare a good share of the image, find CSM's
Principled BSDF at most EEVEE's error against Cycles (and under 2 %), write both heat maps
and put the table between the page's markers, keeping the prose around it.
"""
from csm_tools import shading_parity
from csm_tools.report_io import read_png

PROSE = "# Shading parity\n\nHand-written prose that the tool must keep.\n\n"


def test_quick_run_measures_writes_heat_maps_and_the_table(tmp_path):
    page = tmp_path / "shading-parity.md"
    page.write_text(PROSE + shading_parity.BEGIN + "\nstale\n" + shading_parity.END
                    + "\nAfter.\n", encoding="utf-8")
    scene, _ = shading_parity.open_parity_scene("sphere_row", (128, 72))
    images, covered = shading_parity.measure_scene(scene, 128, 72)
    rows = shading_parity.compare_scene(images, covered)
    assert rows["CSM"]["pixels"] > 0.5 * 128 * 72
    assert rows["CSM"]["mean"] <= rows["EEVEE"]["mean"] and rows["CSM"]["mean"] < 0.02, rows
    assert shading_parity.main(["sphere_row", "--quick", "--out-dir", str(tmp_path)]) == 0
    for engine in ("csm", "eevee"):
        heat = read_png(tmp_path / "images" / f"parity_sphere_row_{engine}.png")
        assert heat.shape[:2] == (72, 128), engine
    text = page.read_text(encoding="utf-8")
    assert text.startswith(PROSE) and text.endswith("\nAfter.\n") and "stale" not in text
    assert "| sphere_row |" in text and "parity_sphere_row_csm.png" in text
