"""The Exact tools: the report against Cycles writes its table and passes the mark on a
small built scene; the benchmark writes its table."""

from csm_tools import exact_bench, exact_report


def test_exact_report_writes_its_table_and_exact_matches_cycles(tmp_path):
    page = tmp_path / "ground-truth.md"
    page.write_text(f"# Ground truth\n\n{exact_report.BEGIN}\n{exact_report.END}\n",
                    encoding="utf-8")
    assert exact_report.main(["--scenes", "mirrored", "--resolution", "160x90",
                              "--write", str(page)]) == 0
    text = page.read_text(encoding="utf-8")
    row = next(line for line in text.splitlines() if line.startswith("| mirrored |"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    exact_mismatch = float(cells[1 + exact_report.FILTERS.index("EXACT")])
    assert exact_mismatch <= 0.02, row


def test_exact_bench_writes_its_table(tmp_path):
    page = tmp_path / "benchmarks.md"
    page.write_text(f"# Benchmarks\n\n{exact_bench.BEGIN}\n{exact_bench.END}\n",
                    encoding="utf-8")
    assert exact_bench.main(["--scenes", "shadow_test", "--resolution", "160x90",
                             "--repeats", "1", "--write", str(page)]) == 0
    assert "| shadow_test |" in page.read_text(encoding="utf-8")
