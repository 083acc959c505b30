"""The Benchmarks page (bench/results_page.py): generated from the bench result files, current."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("results_page", ROOT / "bench" / "results_page.py")
results_page = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(results_page)

RECORD = {
    "bench": "bench_fast",
    "command": "python bench/bench_fast.py --json bench/results/bench_fast.json",
    "date": "2026-11-25 14:36 UTC",
    "machine": {
        "cpu": "Some CPU",
        "cores": 2,
        "load_average_1min": 5.0,
        "python": "3.11.7",
        "torch": "2.13.0+cpu",
        "numba": "0.68.1",
        "system": "Linux",
    },
    "notes": "batch 32",
    "figures": {"compiled, s/epoch": 3.18, "torch / compiled": 9.16, "|a - b|": 7.46e-08},
}


def test_committed_page_is_current():
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    assert page == results_page.page(), "run `python bench/results_page.py > docs/benchmarks.md`"


def test_figures_machine_and_date_come_from_the_result_file(tmp_path: Path):
    bench, results = tmp_path / "bench", tmp_path / "bench" / "results"
    results.mkdir(parents=True)
    (bench / "bench_fast.py").write_text('"""Fast thing vs slow thing.\n\nMore."""\n')
    (bench / "bench_slow.py").write_text('"""Slow thing."""\n')
    (results / "bench_fast.json").write_text(json.dumps(RECORD))
    page = results_page.page(results, bench)
    assert "| `bench/bench_fast.py` | Fast thing vs slow thing. | yes |" in page
    assert "| `bench/bench_slow.py` | Slow thing. | none yet |" in page
    assert "Measured 2026-11-25 14:36 UTC on Some CPU, 2 cores (a shared machine: load" in page
    assert f"Regenerate: `{RECORD['command']}`" in page
    assert "| torch / compiled | 9.16 |" in page
    assert "| \\|a - b\\| | 7.5e-08 |" in page  # a | inside a cell is escaped
    assert "## bench_slow" not in page


def test_an_idle_machine_is_not_called_shared(tmp_path: Path):
    (tmp_path / "results").mkdir()
    idle = {**RECORD, "machine": {**RECORD["machine"], "load_average_1min": 0.3}}
    (tmp_path / "results" / "bench_fast.json").write_text(json.dumps(idle))
    page = results_page.page(tmp_path / "results", tmp_path)
    assert "2 cores (load average 0.3 at the end)" in page


def test_a_gpu_in_the_record_is_named_beside_the_cores(tmp_path: Path):
    (tmp_path / "results").mkdir()
    on_gpu = {**RECORD, "machine": {**RECORD["machine"], "gpu": "Some GPU"}}
    (tmp_path / "results" / "bench_fast.json").write_text(json.dumps(on_gpu))
    page = results_page.page(tmp_path / "results", tmp_path)
    assert "on Some CPU, 2 cores, GPU Some GPU (a shared machine" in page


def test_two_result_files_of_one_bench_are_told_apart_by_file(tmp_path: Path):
    (tmp_path / "results").mkdir()
    for name in ("bench_fast.json", "bench_fast_gpu.json"):
        (tmp_path / "results" / name).write_text(json.dumps(RECORD))
    page = results_page.page(tmp_path / "results", tmp_path)
    assert "\n## bench_fast\n" in page and "\n## bench_fast (bench_fast_gpu.json)\n" in page
