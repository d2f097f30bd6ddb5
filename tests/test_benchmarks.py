"""The benchmark scripts still run: a tiny accuracy-versus-time sweep end to end.

No timing is asserted (timings belong in the benchmark's own output); this checks that the
reference is the first row, the swept settings are the ones named, and the outputs are written.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_accuracy_vs_time_writes_table_json_and_plot_with_paper_as_reference(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "accuracy_vs_time.py"), "--towers", "2", "--samples", "2",
         "--workers", "1", "--phi", "0", "--query", "fall", "--no-k-sweep",
         "--only", "default,default-1/120s-uncapped", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "accuracy_vs_time.json").read_text())
    assert data["towers"] == 2 and data["samples"] == 2 and data["queries"] == ["fall"]
    rows = {row["config"]: row for row in data["rows"]}
    assert [row["config"] for row in data["rows"]][0] == "paper"
    assert set(rows) >= {"paper", "default", "default-1/120s-uncapped"}
    paper = rows["paper"]
    assert paper["speedup_vs_paper"] == 1.0 and paper["mean_abs_dff"] == 0.0 and paper["per_sample_agreement"] == 1.0
    for row in rows.values():
        assert row["failed_samples"] == 0
        assert math.isfinite(row["wall_s_per_prediction"]) and row["wall_s_per_prediction"] > 0
    # the uncapped candidate really runs 1/120 s steps on these 0.2 m blocks
    assert rows["default-1/120s-uncapped"]["settings"]["time_step_s"] == 1 / 120
    assert rows["default-1/120s-uncapped"]["settings"]["max_step_fraction_of_time_scale"] == 0.1
    assert "| paper |" in (tmp_path / "accuracy_vs_time.md").read_text()
    assert (tmp_path / "accuracy_vs_time.png").stat().st_size > 1000
