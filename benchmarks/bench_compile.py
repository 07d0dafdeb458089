"""What compiling warptex's kernels costs a user, on the CPU and for a CUDA GPU (sm_90).

Warp compiles each of warptex's Warp modules the first time one of its kernels runs and caches the
result; a new user, a new Warp release or a changed kernel starts from an empty cache. This script
measures that cold start, every measurement in a fresh process with a fresh temporary kernel cache
(``WARP_CACHE_PATH``):

- **jobs**: what a user runs (``warptex render``, ``warptex fit`` with a few iterations, each
  technique's forward and forward+backward on a small G-buffer), timed cold (wall clock of the
  whole process), with the Warp modules each one compiled;
- **modules**: every module those jobs compile, its CPU compile time (after Warp's one-time
  compiler start-up in the process, reported on its own row; with Warp 1.19 that includes the
  precompiled header of Warp's own headers, which each compiling thread of a job builds once) and
  its ahead-of-time compile time for an sm_90 GPU (``wp.compile_aot_module``; NVRTC runs without
  a GPU or driver, in one thread, so this machine's figure is what a GPU user waits for);
- each job's totals: the sum of its modules' CPU and sm_90 compile times. The CPU's lane kernels
  live in CPU-only modules (``warptex.splat8.lanes``...); where a CPU job compiles one, the same job
  on a GPU compiles the one-pixel module it stands for (``warptex.splat8``), and its sm_90 figures
  are that module's.

    python benchmarks/bench_compile.py                     # everything (a few minutes)
    python benchmarks/bench_compile.py --json compile.json --jobs render "triplanar fwd"
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from warptex.kernels.family import LANES_SUFFIX

# Small inputs: the jobs measure compiling, not running.
_SETUP = """
import numpy as np, warp as wp, warptex as wt
from warptex.scenes.terrain import terrain
from warptex.scenes import terrain_camera
g = wt.rasterize(terrain(resolution=(33, 33)), terrain_camera((64, 64)))
rng = np.random.default_rng(0)
def texture(grad=False, channels=4):
    return wt.Texture(rng.random((32, 32, channels)).astype(np.float32), requires_grad=grad)
def layers(grad=False):
    return wt.TextureArray(rng.random((4, 32, 32, 4)).astype(np.float32), requires_grad=grad)
maps = wt.TextureArray(rng.random((1, 9, 9, 4)).astype(np.float32), mipmaps=False)
uv = rng.random((1000, 2)).astype(np.float32)
def backward(run):
    tape = wp.Tape()
    with tape:
        out = run()
    out.grad.fill_(1.0)
    tape.backward()
"""

_SNIPPETS = {
    "sample": "wt.sample(texture(GRAD), uv, lod=1.5)",
    "stochastic (hex)": "wt.stochastic(texture(GRAD), uv, 'hex', lod=1.5)",
    "triplanar": "wt.triplanar(g, texture(GRAD), tiling=4.0)",
    "triplanar (hash4)": "wt.triplanar(g, texture(GRAD), tiling=4.0, stochastic='hash4')",
    "triplanar (faces)": "wt.triplanar(g, textures_per_face=[texture(GRAD) for _ in range(6)], tiling=4.0)",
    "triplanar (faces, hash4)": "wt.triplanar(g, textures_per_face=[texture(GRAD) for _ in range(6)], tiling=4.0, stochastic='hash4')",
    "triplanar_normal": "wt.triplanar_normal(g, texture(GRAD, 3), tiling=4.0)",
    "splat": "wt.splat(g, layers(GRAD), maps, tiling=0.2, projection='triplanar', height_blend=0.2)",
    "splat (hex)": "wt.splat(g, layers(GRAD), maps, tiling=0.2, projection='triplanar', height_blend=0.2, stochastic='hex')",
    "splat_atlas": "wt.splat_atlas(g, wt.pack_atlas(layers(), requires_grad=GRAD), *wt.export_index_maps(maps, k=2), tiling=4.0)",
    "bake (triplanar)": "wt.bake(__import__('trimesh').creation.icosphere(), lambda b: wt.triplanar(b, texture(GRAD), tiling=4.0), size=128).color",
}


def _technique_jobs() -> dict:
    jobs = {}
    for name, call in _SNIPPETS.items():
        jobs[f"{name} fwd"] = {"python": _SETUP + call.replace("GRAD", "False")}
        jobs[f"{name} fwd+bwd"] = {"python": _SETUP + f"backward(lambda: {call.replace('GRAD', 'True')})"}
    # A gradient only Warp's generated adjoint gives: the triplanar sharpness.
    sharp = "wt.triplanar(g, texture(), tiling=4.0, sharpness=wp.array([4.0], dtype=float, requires_grad=True))"
    jobs["triplanar fwd+bwd (sharpness)"] = {"python": _SETUP + f"backward(lambda: {sharp})"}
    return jobs


JOBS = {
    "render": {"cli": ["render", "--out", "{tmp}", "--resolution", "512x512"]},
    "bake": {"cli": ["bake", "--out", "{tmp}/asset.glb", "--size", "512"]},
    "fit": {"cli": ["fit", "--out", "{tmp}", "--iters", "4"]},
    **_technique_jobs(),
}

_MODULE_DIR = re.compile(r"^wp_(?P<name>.+)_[0-9a-f]{7}$")


def _fresh_env(cache: str) -> dict:
    env = dict(os.environ)
    env["WARP_CACHE_PATH"] = cache
    return env


def _compiled_modules(cache: str) -> list[str]:
    """Names of the Warp modules compiled into the kernel cache folder ``cache``."""
    names = set()
    for root, dirs, _ in os.walk(cache):
        for d in dirs:
            m = _MODULE_DIR.match(d)
            if m:
                names.add(m.group("name"))
    return sorted(names)


def run_job(name: str, spec: dict) -> dict:
    """Run job ``name`` cold (fresh process, fresh kernel cache); its wall time and modules."""
    with tempfile.TemporaryDirectory(prefix="warptex_compile_") as tmp:
        cache = os.path.join(tmp, "cache")
        if "cli" in spec:
            cmd = [sys.executable, "-m", "warptex", *[a.format(tmp=os.path.join(tmp, "out")) for a in spec["cli"]]]
        else:
            cmd = [sys.executable, "-c", spec["python"]]
        start = time.perf_counter()
        result = subprocess.run(cmd, env=_fresh_env(cache), capture_output=True, text=True, cwd=tmp)
        wall = time.perf_counter() - start
        if result.returncode != 0:
            raise RuntimeError(f"job {name!r} failed:\n{result.stdout[-2000:]}\n{result.stderr[-4000:]}")
        return {"job": name, "cold_wall_s": wall, "modules": _compiled_modules(cache)}


# -- one module, in a child process ---------------------------------------------------------------------

_CHILD = """
import json, os, sys, tempfile, time
import warp as wp
wp.config.quiet = True
name, target = sys.argv[1], sys.argv[2]

from warptex.kernels import native

# warptex's build options (its headers' folder): Warp 1.19 builds a precompiled header of its own
# headers per thread and per set of options, once, before the first module; with other options the
# measured module would build it again.
@wp.kernel(module=native.use("warptex_bench_compile_warm_up"))
def warm_up(a: wp.array(dtype=float)):
    a[0] = 1.0

def build(name):
    if name.startswith("warp.optim"):  # Warp's own (warptex's fit uses its Adam)
        import warp.optim
        return
    from warptex.kernels import all_kernels  # builds every kernel family's configurations
    m = __import__("re").match(r"warptex\\.splat(\\d+)", name)
    all_kernels((int(m.group(1)),) if m else (4,))

t = time.perf_counter()
if target == "cpu":
    wp.load_module("warptex_bench_compile_warm_up", device="cpu", block_dim=1)  # Warp's one-time compiler start-up, its precompiled header
    start_up = time.perf_counter() - t
    build(name)
    t = time.perf_counter()
    wp.load_module(name, device="cpu", block_dim=1)  # the variant a CPU launch loads (Warp 1.17 would build block_dim 256's)
else:
    with tempfile.TemporaryDirectory() as d:
        wp.compile_aot_module("warptex_bench_compile_warm_up", arch=int(target), module_dir=d)
    start_up = time.perf_counter() - t
    build(name)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        wp.compile_aot_module(name, arch=int(target), module_dir=d)
print(json.dumps({"seconds": time.perf_counter() - t, "start_up": start_up}))
"""


def measure_module(name: str, target: str) -> dict:
    """Compile module ``name`` for ``target`` (``"cpu"`` or an sm architecture, e.g. ``"90"``) in a
    fresh process with a fresh kernel cache: ``{"seconds", "start_up"}``."""
    with tempfile.TemporaryDirectory(prefix="warptex_compile_") as tmp:
        script = Path(tmp) / "compile_one.py"  # Warp reads kernel source from files, not from -c
        script.write_text(_CHILD)
        result = subprocess.run([sys.executable, str(script), name, target], env=_fresh_env(os.path.join(tmp, "cache")), capture_output=True, text=True, cwd=tmp)
        if result.returncode != 0:
            raise RuntimeError(f"compiling {name} for {target} failed:\n{result.stderr[-4000:]}")
        return json.loads(result.stdout.strip().splitlines()[-1])


# -- report ---------------------------------------------------------------------------------------------


def _on_gpu(module: str) -> list[str]:
    """The modules a GPU compiles where the CPU compiles ``module``: a lane module's one-pixel
    kernels'; a gradient's lane module also holds the forward lane that keeps what the gradient
    reads (``Kernels.kept_lanes``), which the forward's module stands for on a GPU."""
    one_pixel = module.removesuffix(LANES_SUFFIX)
    if module != one_pixel and one_pixel.endswith(".grad"):
        return [one_pixel, one_pixel.removesuffix(".grad")]
    return [one_pixel]


def run(args, report=print) -> dict:
    jobs = {}
    for name in args.jobs:
        jobs[name] = run_job(name, JOBS[name])
        report(f"job {name:32s} cold {jobs[name]['cold_wall_s']:6.1f} s  modules: {', '.join(jobs[name]['modules'])}")
    targets = ["cpu"] + ([str(a) for a in args.arch] if not args.no_cuda else [])
    # A job compiles its CPU modules; the same job on a GPU compiles, for each CPU-only lane module,
    # the module of the one-pixel kernels it stands for.
    wanted = {}
    for j in jobs.values():
        for m in j["modules"]:
            wanted.setdefault(m, set()).add("cpu")
            for gpu in _on_gpu(m):
                wanted.setdefault(gpu, set()).update(targets[1:])
    table, start_up = {}, {}
    for name in sorted(wanted):
        table[name] = {}
        for target in [t for t in list(targets) if t in wanted[name]]:
            try:
                r = measure_module(name, target)
            except RuntimeError as err:
                if target == "cpu" or "nvrtc" not in str(err).lower():
                    raise
                report(f"sm_{target}: skipped (NVRTC unavailable: {str(err).strip().splitlines()[-1]})")
                targets.remove(target)
                continue
            table[name][target] = r["seconds"]
            start_up.setdefault(target, []).append(r["start_up"])
        report(f"module {name:32s} " + "  ".join(f"{'CPU' if t == 'cpu' else 'sm_' + t} " + (f"{table[name][t]:6.1f} s" if t in table[name] else "     -  ") for t in targets))
    start = {t: min(v) for t, v in start_up.items()}
    report("start-up (once per process)              " + "  ".join(f"{'CPU' if t == 'cpu' else 'sm_' + t} {start[t]:6.1f} s" for t in targets if t in start))

    def job_modules(job: dict, target: str) -> set:
        return set(job["modules"]) if target == "cpu" else {gpu for m in job["modules"] for gpu in _on_gpu(m)}

    totals = {name: {t: sum(table[m][t] for m in job_modules(j, t)) for t in targets} for name, j in jobs.items()}
    return {"jobs": jobs, "modules": table, "start_up": start, "totals": totals, "targets": targets}


def markdown(result: dict) -> str:
    """The tables for the docs (docs/performance.md)."""
    targets = result["targets"]
    head = ["CPU" if t == "cpu" else f"sm_{t}" for t in targets]
    lines = ["| module | " + " | ".join(f"{h} compile (s)" for h in head) + " |", "|---|" + "---:|" * len(targets)]
    start = result["start_up"]
    lines.append("| *Warp's compiler start-up, once per process* | " + " | ".join(f"{start[t]:.1f}" for t in targets) + " |")
    for name, row in result["modules"].items():
        lines.append(f"| `{name}` | " + " | ".join(f"{row[t]:.1f}" if t in row else "—" for t in targets) + " |")
    lines += ["", "| job | cold wall (s) | modules | " + " | ".join(f"{h} total (s)" for h in head) + " |", "|---|---:|---|" + "---:|" * len(targets)]
    for name, job in result["jobs"].items():
        mods = ", ".join(m.removeprefix("warptex.") for m in job["modules"])
        lines.append(f"| {name} | {job['cold_wall_s']:.1f} | {mods} | " + " | ".join(f"{result['totals'][name][t]:.1f}" for t in targets) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--jobs", nargs="+", default=list(JOBS), choices=list(JOBS), metavar="JOB", help=f"jobs to run (default: all: {', '.join(JOBS)})")
    p.add_argument("--arch", nargs="+", type=int, default=[90], help="CUDA architectures to compile for ahead of time (default: 90)")
    p.add_argument("--no-cuda", action="store_true", help="CPU compile times only")
    p.add_argument("--json", type=Path, help="write the results here")
    p.add_argument("--markdown", action="store_true", help="print the docs' tables (docs/performance.md) at the end")
    args = p.parse_args(argv)
    result = run(args)
    if args.markdown:
        print(markdown(result))
    if args.json:
        from warptex.io import _atomic_output

        with _atomic_output(str(args.json)) as tmp:
            Path(tmp).write_text(json.dumps(result, indent=1))
        print(f"json: {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
