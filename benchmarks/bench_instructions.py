"""Instructions per sample of warptex's techniques (and of a peer), counted by valgrind's callgrind.

A count of executed instructions is repeatable whatever else the machine is doing, where a timing
on a shared 2-core machine moves by ±30%: this is the before/after measure for kernel changes
(interleaving the timed runs is the other). Each figure runs a technique's call in a fresh process
under ``valgrind --tool=callgrind`` (one thread: warptex's pool and the peer's) with instrumentation
off (``--instr-atstart=no``) through start-up, imports, compiling (the kernels come from Warp's
cache, filled by a first plain run) and a warm-up call, switches it on (``callgrind_control -i on``)
for ``R`` more calls, and reports their instructions per sample. Instructions are not time: a cache
miss costs many cycles and no instruction, so random access to a large texture is cheap here and
slow on the clock. Warp compiles its CPU modules for the CPU it runs on, and valgrind's has AVX2
and no AVX-512, so these count the AVX2 build of the lanes even on a host with AVX-512.
``--cache-sim`` also has callgrind simulate the caches (its first level and its last, sized as
this machine's) and reports their data misses per sample: how much memory traffic each
implementation makes, though not how well the hardware overlaps it.

    python benchmarks/bench_instructions.py                              # every case, warptex
    python benchmarks/bench_instructions.py --cases "bilinear sphere" --peers drjit torch
    python benchmarks/bench_instructions.py --cases "bilinear random" --passes forward --peers drjit --cache-sim
    python benchmarks/bench_instructions.py --cases "bilinear sphere" --passes forward --formats float32 unorm8

Needs valgrind (Debian's ``valgrind`` package); skips, saying why, without it.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent

# The scene of each case (as bench_samplers.py builds it) and the warptex call it counts.
CASES = {
    "bilinear sphere": ("bilinear", "sphere"),
    "bilinear random": ("bilinear", "random"),
    "trilinear sphere": ("trilinear", "sphere"),
    "triplanar sphere": ("triplanar", "sphere"),
    "triplanar terrain": ("triplanar", "terrain"),
    "splat4 terrain": ("splat4", "terrain"),
    "splat8 sphere": ("splat8", "sphere"),
    "triplanar_normal sphere": ("triplanar_normal", "sphere"),
}

_RUNNER = """
import sys, numpy as np, warp as wp
sys.path.insert(0, {bench!r})
wp.config.quiet = True
wp.init()
import warptex as wt
import peers
from bench_samplers import scene_data, samples, texture, warptex_runs
wt.set_num_threads(1)
technique, scene, impl, passes, repeats, fmt = {technique!r}, {scene!r}, {impl!r}, {passes!r}, {repeats}, {fmt!r}
sizes = {{"sphere": 512, "terrain": 256, "random": 1 << 18}}
tex = texture(1024)
data, objs = scene_data(technique, scene, sizes, tex, {{}})
if impl == "warptex":
    forward, forward_backward = warptex_runs(technique, data, objs, fmt=fmt)
    run = forward if passes == "forward" else forward_backward
else:
    peers.set_device(impl, "cpu")
    peers.set_threads(impl, 1)
    peer = peers.load(impl)[technique]
    state = peer.prepare(data)
    run = (lambda: peer.forward(state)) if passes == "forward" else (lambda: peer.forward_backward(state))
    sync = lambda: peers.synchronize(impl)
import os, subprocess
run()  # compiles (or loads from the cache), allocates
if impl != "warptex":
    sync()
subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=True, capture_output=True)
for _ in range(repeats):
    run()
    if impl != "warptex":
        sync()
subprocess.run(["callgrind_control", "-i", "off", str(os.getpid())], check=True, capture_output=True)
print("SAMPLES", samples(data))
"""


def totals(text: str) -> dict[str, int]:
    """The event totals of a callgrind output file, by event name (``Ir``: instructions; with the
    cache simulation also ``Dr``, ``Dw`` and the misses ``D1mr``, ``D1mw``, ``DLmr``, ``DLmw``)."""
    lines = text.splitlines()
    names = next(line for line in lines if line.startswith("events:")).split()[1:]
    values = [line for line in lines if line.startswith("totals:") or line.startswith("summary:")][-1].split()[1:]
    return {name: int(value) for name, value in zip(names, values)}


def count(case: str, impl: str, passes: str, repeats: int, cache_sim: bool = False, fmt: str = "float32") -> tuple[dict[str, int], int]:
    """``(totals, samples)`` of ``repeats`` calls of ``case`` (after a warm-up call): the event
    totals (:func:`totals`) and the samples a call takes. warptex reads its textures in texel
    format ``fmt``; peers always read float32."""
    technique, scene = CASES[case]
    code = _RUNNER.format(bench=str(HERE), technique=technique, scene=scene, impl=impl, passes=passes, repeats=repeats, fmt=fmt)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        env = {**os.environ, "WARPTEX_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
        command = ["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--cache-sim={'yes' if cache_sim else 'no'}", f"--callgrind-out-file={out}", sys.executable, "-c", code]
        result = subprocess.run(command, capture_output=True, text=True, env=env)
        if result.returncode != 0 or "SAMPLES" not in result.stdout:
            raise RuntimeError(f"{case} {impl} {passes} failed:\n{result.stdout[-2000:]}\n{result.stderr[-3000:]}")
        samples = int(result.stdout.split("SAMPLES")[1].split()[0])
        return totals(out.read_text()), samples


def per_sample(case: str, impl: str, passes: str, repeats: int, cache_sim: bool = False, fmt: str = "float32") -> dict[str, float]:
    """Per sample of a call (``repeats`` calls, averaged): ``instructions``, and with ``cache_sim``
    the simulated first-level (``d1_misses``) and last-level (``ll_misses``) data misses, reads and
    writes together."""
    events, samples = count(case, impl, passes, repeats, cache_sim, fmt)
    n = repeats * samples
    figures = {"instructions": events["Ir"] / n}
    if cache_sim:
        figures["d1_misses"] = (events["D1mr"] + events["D1mw"]) / n
        figures["ll_misses"] = (events["DLmr"] + events["DLmw"]) / n
    return figures


def format_figures(case: str, passes: str, impl: str, figures: dict[str, float]) -> str:
    """One line of the report."""
    line = f"{case:20s} {passes:16s} {impl:15s} {figures['instructions']:10.1f} instructions/sample"
    if "d1_misses" in figures:
        line += f"  {figures['d1_misses']:6.2f} D1 misses/sample  {figures['ll_misses']:6.3f} LL misses/sample"
    return line


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    p.add_argument("--passes", nargs="+", default=["forward", "forward+backward"], choices=["forward", "forward+backward"])
    p.add_argument("--peers", nargs="*", default=[], help="peers to count too (drjit, torch, numpy)")
    p.add_argument("--repeats", type=int, default=2, help="calls counted after the warm-up call (default 2)")
    p.add_argument("--formats", nargs="+", default=["float32"], choices=["float32", "float16", "unorm8", "srgb8"],
                   help="texel formats of warptex's textures, a row each (default float32; peers read float32)")
    p.add_argument("--cache-sim", action="store_true", help="also simulate the caches: data misses per sample (slower)")
    p.add_argument("--json", type=Path, help="write the figures here")
    args = p.parse_args(argv)
    if shutil.which("valgrind") is None:
        print("bench_instructions: skipped (valgrind is not installed: apt-get install valgrind)")
        return 0
    subprocess.run([sys.executable, str(HERE / "bench_samplers.py"), "--quick", "--peers", "--no-scaling", "--techniques", *sorted({CASES[c][0] for c in args.cases})],
                   check=True, capture_output=True)  # fills Warp's kernel cache outside valgrind  # fmt: skip
    rows = []
    for case in args.cases:
        for passes in args.passes:
            for impl, fmt in [*(("warptex", f) for f in args.formats), *((peer, "float32") for peer in args.peers)]:
                name = impl if fmt == "float32" else f"{impl} {fmt}"
                try:
                    figures = per_sample(case, impl, passes, args.repeats, args.cache_sim, fmt)
                except (RuntimeError, KeyError) as err:
                    print(f"{case:20s} {passes:16s} {name:15s} skipped ({str(err).splitlines()[0]})", flush=True)
                    continue
                rows.append({"case": case, "pass": passes, "impl": impl, "format": fmt, **{f"{k}_per_sample": v for k, v in figures.items()}})
                print(format_figures(case, passes, name, figures), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
