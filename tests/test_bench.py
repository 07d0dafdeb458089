"""The samplers benchmark runs on a fresh install (--quick), checks its peers against warptex, and
writes its JSON and plot. Speed itself is measured by the benchmark, never asserted here."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_samplers.py"


def run_script(script, *args) -> subprocess.CompletedProcess:
    """A benchmark script run with ``args`` in a process of its own, which must succeed (its
    output's tails otherwise say why)."""
    result = subprocess.run([sys.executable, str(script), *map(str, args)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_quick_benchmark_writes_json_and_plot(tmp_path):
    out = tmp_path / "bench"
    result = run_script(BENCH, "--quick", "--threads", "4", "--thread-counts", "2", "--peers", "numpy", "--techniques", "bilinear", "triplanar", "splat4", "--json", str(tmp_path / "r.json"), "--out", str(out))
    data = json.loads((tmp_path / "r.json").read_text())
    records = data["records"]
    for technique in ("bilinear", "triplanar", "splat4"):
        mine = [r for r in records if r["technique"] == technique and r["impl"] == "warptex"]
        assert {(r["pass"], r["threads"]) for r in mine} == {(p, t) for p in ("forward", "forward+backward") for t in (1, 2, 4)}
        assert all(r["seconds"] > 0 and r["msamples_per_s"] > 0 for r in mine)
        assert all(r["threaded_max_abs_diff"] == 0.0 for r in mine)  # 4 chunks of >= 16384 pixels: bit-identical
        numpy_peer = [r for r in records if r["technique"] == technique and r["impl"] == "numpy"]
        assert numpy_peer and all(r["max_abs_diff"] < 1e-4 for r in numpy_peer), numpy_peer
    assert set(data["scaling"]["pixels"]) and set(data["scaling"]["texture"])
    assert (out / "scaling.png").stat().st_size > 1000
    assert "x" in result.stdout and "warptex time" in result.stdout
    assert "thread scaling (speed-up over 1 thread): 2 thr, 4 thr" in result.stdout
    table = result.stdout[result.stdout.index("peers against warptex") :].splitlines()
    for technique in ("bilinear", "triplanar", "splat4"):
        mine = {r["pass"]: r["seconds"] for r in records if r["technique"] == technique and r["scene"] == "sphere" and r["impl"] == "warptex" and r["threads"] == 4}
        peer = {r["pass"]: r["seconds"] for r in records if r["technique"] == technique and r["scene"] == "sphere" and r["impl"] == "numpy"}
        row = next(line for line in table if line.split()[:2] == [technique, "sphere"])
        want = " / ".join(f"{peer[p] / mine[p]:5.2f}" if p in peer else "  -  " for p in ("forward", "forward+backward"))
        assert row.rstrip().endswith(want.strip()), (row, want)  # each peer's time over warptex's, same threads



@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_formats_add_rows_of_compact_texels_in_the_same_rounds(tmp_path):
    result = run_script(BENCH, "--quick", "--threads", "2", "--peers", "--no-scaling", "--techniques", "bilinear", "splat4", "--formats", "float32", "unorm8", "float16", "--texture-size", "64", "--json", str(tmp_path / "r.json"))
    result_json = json.loads((tmp_path / "r.json").read_text())
    records = result_json["records"]
    assert result_json["settings"]["texture_size"] == 64 and "texture: 64² RGBA with mips" in result.stdout
    for technique in ("bilinear", "splat4"):
        for fmt in ("unorm8", "float16"):
            mine = [r for r in records if r["technique"] == technique and r.get("format") == fmt]
            assert {(r["scene"], r["pass"]) for r in mine} >= {("sphere", "forward"), ("sphere", "forward+backward")}
            assert all(r["impl"] == f"warptex {fmt}" and r["threads"] == 2 and r["seconds"] > 0 for r in mine)
            assert all(r["max_abs_diff"] < 0.02 for r in mine if r["pass"] == "forward")  # 8-bit and half rounding of the same texels
    table = result.stdout[result.stdout.index("texel formats against float32") :].splitlines()
    f32 = {r["pass"]: r["seconds"] for r in records if r["technique"] == "bilinear" and r["scene"] == "sphere" and r["impl"] == "warptex" and r["threads"] == 2}
    u8 = {r["pass"]: r["seconds"] for r in records if r["technique"] == "bilinear" and r["scene"] == "sphere" and r.get("format") == "unorm8"}
    row = next(line for line in table if line.split()[:2] == ["bilinear", "sphere"])
    assert row.rstrip().endswith(" / ".join(f"{f32[p] / u8[p]:5.2f}" for p in ("forward", "forward+backward")).strip()), row


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_limit_and_runs_give_the_c_loop_and_each_ratio_spread(tmp_path):
    """--limit times the plain C loop beside the peers; --runs 2 times every row twice, and the
    summary gives each ratio as the lowest and highest of the runs' ratios."""
    result = run_script(BENCH, "--quick", "--threads", "2", "--peers", "numpy", "--limit", "--runs", "2", "--no-scaling", "--techniques", "bilinear", "--json", str(tmp_path / "r.json"))
    written = json.loads((tmp_path / "r.json").read_text())
    records = written["records"]
    assert all(len(r["run_seconds"]) == 2 and r["seconds"] == min(r["run_seconds"]) for r in records)
    if "peer limit: skipped" in result.stdout:
        pytest.skip("no C compiler with OpenMP here: " + result.stdout.split("peer limit: skipped", 1)[1].splitlines()[0])
    # the memory the run gets: a load's latency per working set, and the first size past the cache
    # (a load waiting over 3x the fastest size's), beside the texture's level 0 (256² in --quick)
    memory = written["memory"]
    latency = {int(mb): ns for mb, ns in memory["latency_ns"].items()}
    assert list(latency) == [1, 2, 4, 8] and all(ns > 0 for ns in latency.values())
    past = [mb for mb, ns in latency.items() if ns > 3 * min(latency.values())]
    assert memory["cache_outside_mb"] == (past[0] if past else None)
    assert memory["level0_mb"] == {"float32": 1.0, "float16": 0.5, "8 bits": 0.25}
    assert "memory this run gets" in result.stdout and "the texture's level 0 is 1 MB in float32" in result.stdout
    limit = [r for r in records if r["impl"] == "limit"]
    assert {(r["scene"], r["pass"]) for r in limit} == {("sphere", "forward"), ("random", "forward")}
    assert all(r["max_abs_diff"] < 1e-5 for r in limit)
    table = result.stdout[result.stdout.index("peers against warptex") :].splitlines()
    impls = table[1].split()[4:]  # technique, scene, "warptex", "ms", then the peers' columns
    for scene in ("sphere", "random"):
        mine = next(r for r in records if r["scene"] == scene and r["impl"] == "warptex" and r["pass"] == "forward" and r["threads"] == 2)
        ref = next(r for r in limit if r["scene"] == scene)
        ratios = [a / b for a, b in zip(ref["run_seconds"], mine["run_seconds"])]
        row = next(line for line in table if line.split()[:2] == ["bilinear", scene])
        cells = row.split()[5:]  # after "technique scene ms / ms": a "fwd / fwd+bwd" triple per column
        assert cells[3 * impls.index("limit") :][:3] == [f"{min(ratios):.2f}–{max(ratios):.2f}", "/", "-"], row


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_processes_merge_every_process_runs_into_each_ratio_spread(tmp_path):
    """--processes 2 runs the benchmark in two fresh processes; each figure keeps the runs of both,
    in turn, and the summary over both gives each ratio's spread over all four paired runs."""
    result = run_script(BENCH, "--quick", "--thread-counts", "2", "--threads", "2", "--peers", "numpy", "--runs", "2", "--processes", "2", "--no-scaling", "--techniques", "bilinear", "--json", str(tmp_path / "r.json"))
    assert result.stdout.count("== process ") == 2 and "== the 2 processes together (2 runs each)" in result.stdout
    written = json.loads((tmp_path / "r.json").read_text())
    assert written["processes"] == 2
    records = written["records"]
    assert {(r["scene"], r["impl"], r["pass"]) for r in records} >= {(s, i, "forward") for s in ("sphere", "random") for i in ("warptex", "numpy")}
    assert all(len(r["run_seconds"]) == 4 and r["seconds"] == min(r["run_seconds"]) for r in records)
    table = result.stdout[result.stdout.index("== the 2 processes together") :]
    table = table[table.index("peers against warptex") :].splitlines()
    for scene in ("sphere", "random"):
        mine = next(r for r in records if r["scene"] == scene and r["impl"] == "warptex" and r["pass"] == "forward" and r["threads"] == 2)
        peer = next(r for r in records if r["scene"] == scene and r["impl"] == "numpy" and r["pass"] == "forward")
        ratios = [a / b for a, b in zip(peer["run_seconds"], mine["run_seconds"])]
        row = next(line for line in table if line.split()[:2] == ["bilinear", scene])
        assert row.split()[5:8] == [f"{min(ratios):.2f}–{max(ratios):.2f}", "/", "-"], row


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_call_cost_rows_time_small_calls_against_torch(tmp_path):
    pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    result = run_script(BENCH, "--call-cost", "--quick", "--calls", "2", "--json", str(tmp_path / "c.json"))
    rows = json.loads((tmp_path / "c.json").read_text())["call_cost"]
    projections = [r for r in rows if r["technique"] != "sample"]
    assert {(r["technique"], r["impl"]) for r in projections} == {(f, i) for f in ("triplanar", "biplanar", "splat") for i in ("warptex", "warptex out=")}
    assert all(r["seconds"] > 0 for r in projections) and "1-pixel calls (median us): triplanar" in result.stdout
    rows = [r for r in rows if r["technique"] == "sample"]
    impls = ("warptex", "warptex out=", "warptex.torch", "torch")
    want = {(n, p, i) for n in (1, 1024, 65536) for p in ("forward", "forward+backward") for i in impls} | {(n, "forward", "warptex new uv") for n in (1, 1024, 65536)}
    assert {(r["samples"], r["pass"], r["impl"]) for r in rows} == want
    assert all(r["seconds"] > 0 and r["max_abs_diff"] < 1e-5 for r in rows)  # torch computes what warptex computes
    table = result.stdout[result.stdout.index("call cost") :].splitlines()
    for r in rows:
        if r["impl"] in ("warptex", "warptex new uv", "warptex.torch"):
            torch_s = next(t["seconds"] for t in rows if t["impl"] == "torch" and t["samples"] == r["samples"] and t["pass"] == r["pass"])
            line = next(line for line in table if line.split()[:2] == [str(r["samples"]), r["pass"]])
            assert f"({r['seconds'] / torch_s:5.2f}x)" in line, (line, r)


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_figures_are_timed_in_interleaved_rounds(monkeypatch):
    """Each round runs every figure in turn (pause, setup, untimed call, timed call), and a figure is
    its fastest timed call, so drift of the host over the rounds lands on every figure alike."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        import bench_samplers
    finally:
        sys.path.remove(str(BENCH.parent))
    events, clock = [], [0.0]
    durations = {"a": iter([9, 5, 9, 7, 9, 6]), "b": iter([9, 4, 9, 8, 9, 3])}  # untimed, timed, ... per round

    class FakeTime:
        @staticmethod
        def sleep(seconds):
            events.append(("pause", seconds))

        @staticmethod
        def perf_counter():
            return clock[0]

    def figure(name):
        def run():
            events.append(("run", name))
            clock[0] += next(durations[name])

        return (run, lambda: events.append(("sync", name)), lambda: events.append(("setup", name)))

    monkeypatch.setattr(bench_samplers, "time", FakeTime)
    best = bench_samplers.interleaved_best({"a": figure("a"), "b": figure("b")}, repeats=3, pause=0.25)
    assert best == {"a": 5, "b": 3}
    block = lambda n: [("pause", 0.25), ("setup", n), ("run", n), ("sync", n), ("run", n), ("sync", n)]  # noqa: E731
    assert events == (block("a") + block("b")) * 3


BENCH_TORCH = BENCH.parent / "bench_torch.py"
BENCH_VIEWS = BENCH.parent / "bench_views.py"


@pytest.mark.skipif(not BENCH_TORCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_bridge_overhead_benchmark_checks_and_reports(tmp_path):
    pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    result = run_script(BENCH_TORCH, "--resolution", "32", "--texture-size", "16", "--repeats", "1", "--json", str(tmp_path / "t.json"))
    rows = json.loads((tmp_path / "t.json").read_text())["rows"]
    assert {(r["technique"], r["pass"]) for r in rows} == {(t, p) for t in ("triplanar", "splat") for p in ("forward", "forward+backward")}
    assert all(r["max_abs_diff"] <= 1e-5 and r["native_s"] > 0 and r["bridge_s"] > 0 for r in rows)
    assert "bridge/native" in result.stdout


@pytest.mark.skipif(not BENCH_VIEWS.exists(), reason="benchmarks/ is not part of this checkout")
def test_batched_views_benchmark_reports(tmp_path):
    result = run_script(BENCH_VIEWS, "--views", "2", "--resolution", "24x32", "--iters", "1", "--repeats", "1", "--json", str(tmp_path / "v.json"))
    rows = json.loads((tmp_path / "v.json").read_text())["rows"]
    assert rows[0]["api"] == "warptex.fit.fit_splat" and all(r["batch_s"] > 0 and r["loop_s"] > 0 for r in rows)
    assert "loop/batch" in result.stdout


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_instruction_counts_read_callgrind_events_per_sample(monkeypatch):
    """``bench_instructions`` reads callgrind's totals by event name (their order follows the
    ``events:`` line, which the cache simulation lengthens) and divides by the samples counted."""
    sys.path.insert(0, str(BENCH.parent))
    try:
        import bench_instructions as bi
    finally:
        sys.path.remove(str(BENCH.parent))
    plain = "version: 1\ncmd: python\nevents: Ir\nfn=(1) f\n0 5\nsummary: 4000\ntotals: 4000\n"
    simulated = "events: Ir Dr Dw I1mr D1mr D1mw ILmr DLmr DLmw\nsummary: 4000 900 300 7 250 50 7 20 4\n"
    assert bi.totals(plain) == {"Ir": 4000}
    assert bi.totals(simulated) == {"Ir": 4000, "Dr": 900, "Dw": 300, "I1mr": 7, "D1mr": 250, "D1mw": 50, "ILmr": 7, "DLmr": 20, "DLmw": 4}
    monkeypatch.setattr(bi, "count", lambda case, impl, passes, repeats, cache_sim=False, fmt="float32": (bi.totals(simulated if cache_sim else plain), 50))
    assert bi.per_sample("bilinear random", "warptex", "forward", 2) == {"instructions": 40.0}
    figures = bi.per_sample("bilinear random", "warptex", "forward", 2, cache_sim=True)
    assert figures == {"instructions": 40.0, "d1_misses": 3.0, "ll_misses": 0.24}
    line = bi.format_figures("bilinear random", "forward", "warptex", figures)
    assert "40.0 instructions/sample" in line and "3.00 D1 misses/sample" in line and "0.240 LL misses/sample" in line


DEVICE_CHECKS = BENCH.parent / "device_checks.sh"


@pytest.mark.skipif(not DEVICE_CHECKS.exists(), reason="benchmarks/ is not part of this checkout")
def test_the_device_checks_script_takes_its_commands():
    """benchmarks/device_checks.sh runs once on a GPU that a session holds for minutes: a mistake
    found there costs the run. Here, without one: the script parses, each of its bench_samplers
    command lines is one the benchmark takes (on the CPU), and ``--atomics`` asks for a GPU."""
    text = DEVICE_CHECKS.read_text()
    assert subprocess.run(["bash", "-n", str(DEVICE_CHECKS)], capture_output=True).returncode == 0
    sys.path.insert(0, str(BENCH.parent))
    try:
        import bench_samplers
    finally:
        sys.path.remove(str(BENCH.parent))
    lines = [line.split("benchmarks/bench_samplers.py", 1)[1] for line in text.splitlines() if line.lstrip().startswith("step ") and "bench_samplers.py" in line]
    assert len(lines) == 3
    for line in lines:
        argv = [w.strip('"').replace("$DEVICE", "cpu").replace("$OUT", "out") for w in line.split()]
        if "--atomics" in argv:
            with pytest.raises(SystemExit):
                bench_samplers.parse(argv)
        else:
            args = bench_samplers.parse(argv)
            assert args.device == "cpu" and args.json is not None
    assert "tests/test_cuda.py" in text


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_the_formats_yardstick_builds_as_its_header_says(tmp_path):
    """benchmarks/formats_yardstick.c (issue 48's C loops, cited in docs/performance.md) compiles
    with the command its header gives, warnings as errors, so the figures stay reproducible."""
    source = BENCH.parent / "formats_yardstick.c"
    header = source.read_text().split("*/", 1)[0]
    assert "gcc -O3 -march=native -fopenmp benchmarks/formats_yardstick.c" in header
    if shutil.which("gcc") is None:
        pytest.skip("no gcc on PATH")
    done = subprocess.run(["gcc", "-O3", "-march=native", "-fopenmp", "-Wall", "-Werror", str(source), "-o", str(tmp_path / "y"), "-lm"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.skipif(not BENCH.exists(), reason="benchmarks/ is not part of this checkout")
def test_uv_grads_make_every_forward_backward_take_the_uvs_gradients(tmp_path):
    """--uv-grads: warptex's and the autodiff peers' forward+backward rows take the UVs' gradients
    (marked so in the JSON and the summary); other techniques are refused before anything runs."""
    try:
        import torch  # noqa: F401

        peers = ["torch"]
    except ImportError:
        peers = []
    result = run_script(BENCH, "--quick", "--threads", "2", "--no-scaling", "--techniques", "bilinear", "trilinear", "--uv-grads", "--texture-size", "64",
                        "--peers", *peers, "--json", str(tmp_path / "u.json"))  # fmt: skip
    records = json.loads((tmp_path / "u.json").read_text())["records"]
    backward = [r for r in records if r["pass"] == "forward+backward"]
    assert backward and all(r.get("uv_grads") for r in backward) and not any(r.get("uv_grads") for r in records if r["pass"] == "forward")
    assert {r["impl"] for r in backward} == {"warptex", *peers}
    if peers:
        assert "(gradients of the texels and the UVs: --uv-grads)" in result.stdout
    refused = subprocess.run([sys.executable, str(BENCH), "--quick", "--uv-grads", "--techniques", "triplanar"], capture_output=True, text=True, timeout=600)
    assert refused.returncode == 2 and "--uv-grads times UV gradients of bilinear and trilinear" in refused.stderr
