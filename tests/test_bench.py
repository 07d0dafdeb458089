"""The samplers benchmark runs on a fresh install (--quick), checks its peers against warptex, and
writes its JSON and plot. Speed itself is measured by the benchmark, never asserted here."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_samplers.py"


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_quick_benchmark_writes_json_and_plot(tmp_path):
    out = tmp_path / "bench"
    result = subprocess.run(
        [sys.executable, str(BENCH), "--quick", "--threads", "4", "--peers", "numpy", "--techniques", "bilinear", "triplanar", "splat4", "--json", str(tmp_path / "r.json"), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    data = json.loads((tmp_path / "r.json").read_text())
    records = data["records"]
    for technique in ("bilinear", "triplanar", "splat4"):
        mine = [r for r in records if r["technique"] == technique and r["impl"] == "warptex"]
        assert {(r["pass"], r["threads"]) for r in mine} == {(p, t) for p in ("forward", "forward+backward") for t in (1, 4)}
        assert all(r["seconds"] > 0 and r["msamples_per_s"] > 0 for r in mine)
        assert all(r["threaded_max_abs_diff"] == 0.0 for r in mine)  # 4 chunks of >= 16384 pixels: bit-identical
        numpy_peer = [r for r in records if r["technique"] == technique and r["impl"] == "numpy"]
        assert numpy_peer and all(r["max_abs_diff"] < 1e-4 for r in numpy_peer), numpy_peer
    assert set(data["scaling"]["pixels"]) and set(data["scaling"]["texture"])
    assert (out / "scaling.png").stat().st_size > 1000
    assert "x" in result.stdout and "warptex time" in result.stdout
