"""Whole jobs as they grow: peak memory and wall time of ``warptex render`` and ``warptex bake``
against pixels × samples (issue 52).

Each job runs as a user runs it, a fresh process (imports, warm kernel cache), its peak resident
memory read from the kernel's accounting of that child (``os.wait4``'s ``ru_maxrss``), its wall
time around it. The table gives each job's peak, its ratio to the smallest job's peak, the spread
among the renders and among the bakes (the tiles keep memory flat: the bar is 1.3×), and its wall time per million samples (the work grows with
pixels × samples: time should too).

    python benchmarks/bench_jobs.py                      # the renders and bakes of the issue
    python benchmarks/bench_jobs.py --quick              # smaller jobs, for a look
    python benchmarks/bench_jobs.py --json jobs.json

The time check of the issue (``2048² × 16`` against 16 × ``512² × 16``) is in the summary: the
two are run back to back, ``--repeats`` times, interleaved, and the minimum of each is taken.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

RENDERS = [(512, 4), (1024, 4), (2048, 4), (4096, 4), (2048, 16)]
BAKES = [2048, 4096, 8192]


def run(command: list[str]) -> tuple[float, float, str]:
    """``(peak RSS in MB, wall seconds, stderr)`` of ``command`` run as a child process."""
    start = time.perf_counter()
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = child.stderr.read()
    _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed ({child.returncode}): {err.strip()[-500:]}")
    return usage.ru_maxrss / 1024.0, seconds, err


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller jobs: renders up to 1024², bakes up to 2048²")
    parser.add_argument("--repeats", type=int, default=1, help="runs of the two jobs of the time check, interleaved (default 1)")
    parser.add_argument("--mesh", default=str(DATA / "meshes" / "bunny.ply"), help="the mesh to bake (default: ../shared/data/meshes/bunny.ply)")
    parser.add_argument("--texture", default=str(DATA / "textures" / "brick.png"), help="the bake's texture (default: ../shared/data/textures/brick.png)")
    parser.add_argument("--json", default=None, help="write the results here too")
    args = parser.parse_args()
    if not Path(args.mesh).is_file() or not Path(args.texture).is_file():
        sys.exit(f"bench_jobs: {args.mesh} or {args.texture} not found (the shared data beside the repository)")
    warptex = [sys.executable, "-m", "warptex"]
    renders = [(r, s) for r, s in RENDERS if not args.quick or r <= 1024]
    bakes = [b for b in BAKES if not args.quick or b <= 2048]
    rows = []
    out = Path(tempfile.mkdtemp(prefix="bench_jobs-"))
    try:
        run([*warptex, "render", "--out", str(out / "warm"), "--resolution", "64x64"])  # compiles what a cold cache lacks
        for size, samples in renders:
            rss, seconds, _ = run([*warptex, "render", "--out", str(out / "render"), "--resolution", f"{size}x{size}", "--samples", str(samples)])
            rows.append({"job": f"render {size}² × {samples}", "units": size * size * samples, "rss_mb": rss, "seconds": seconds})
            print(f"{rows[-1]['job']:>22}: {rss:7.0f} MB  {seconds:7.1f} s", flush=True)
        for size in bakes:
            rss, seconds, _ = run([*warptex, "bake", "--mesh", args.mesh, "--texture", args.texture, "--size", str(size), "--out", str(out / "bake" / "asset.glb")])
            rows.append({"job": f"bake {size}²", "units": size * size, "rss_mb": rss, "seconds": seconds})
            print(f"{rows[-1]['job']:>22}: {rss:7.0f} MB  {seconds:7.1f} s", flush=True)
        small = large = float("inf")
        if not args.quick:
            for _ in range(args.repeats):  # the time check: 2048² × 16 against 16 × (512² × 16), interleaved
                small = min(small, run([*warptex, "render", "--out", str(out / "t"), "--resolution", "512x512", "--samples", "16"])[1])
                large = min(large, run([*warptex, "render", "--out", str(out / "t"), "--resolution", "2048x2048", "--samples", "16"])[1])
    finally:
        shutil.rmtree(out, ignore_errors=True)
    lowest = min(r["rss_mb"] for r in rows)
    print(f"\n{'job':>22}  {'peak RSS':>9}  {'÷ smallest':>10}  {'wall':>8}  {'s per M units':>13}")
    for r in rows:
        print(f"{r['job']:>22}  {r['rss_mb']:7.0f} MB  {r['rss_mb'] / lowest:9.2f}×  {r['seconds']:6.1f} s  {r['seconds'] / (r['units'] / 1e6):13.3f}")
    summary = {"jobs": rows}
    print()
    for kind in ("render", "bake"):  # each job's own: a render holds the terrain's layers, a bake one texture
        peaks = [r["rss_mb"] for r in rows if r["job"].startswith(kind)]
        if peaks:
            summary[f"{kind}_rss_spread"] = max(peaks) / min(peaks)
            print(f"peak RSS of {kind}s: {min(peaks):.0f}-{max(peaks):.0f} MB, the largest {max(peaks) / min(peaks):.2f}× the smallest (bar: 1.3×, each <= 1.5 GB + textures)")
    if not args.quick:
        ratio = large / (16 * small)
        print(f"time: render 2048² × 16 took {large:.1f} s, 512² × 16 {small:.1f} s: {ratio:.2f}× 16 × the small one (bar: <= 1.2×)")
        summary.update({"render_512_16_s": small, "render_2048_16_s": large, "time_ratio": ratio})
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
