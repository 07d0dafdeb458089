"""CI: compile every warptex Warp module for a CUDA GPU (sm_90) ahead of time, without a GPU.

No GPU is lent to this project's CI, so the CUDA tests (tests/test_cuda.py) skip there; this keeps
the CUDA build from breaking unseen. ``wp.compile_aot_module`` runs NVRTC, which ships in the
warp-lang wheel and needs no GPU or driver. Every module of ``warptex.kernels.all_kernels()`` is
compiled in a fresh process with an empty kernel cache, side by side on every core, and its time
printed (the compile bar, 30 s a module on this machine, is measured by
benchmarks/bench_compile.py, not here: a loaded CI machine would make it flaky). Exits non-zero
if any module fails to compile.

    python .ci/compile_cuda.py [--arch 90] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

_CHILD = """
import json, os, shutil, sys, tempfile, time
import warp as wp
wp.config.quiet = True
from warptex.kernels import all_kernels
name, arch, keep = sys.argv[1], int(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else None
all_kernels()
t = time.perf_counter()
with tempfile.TemporaryDirectory() as d:
    wp.compile_aot_module(name, arch=arch, module_dir=d)
    seconds = time.perf_counter() - t
    if keep:  # laid out as Warp's kernel cache: <keep>/<warp version>/<module id>/<module id>.{cu,meta,sm90.cubin}
        (meta,) = [f for f in os.listdir(d) if f.endswith(".meta")]
        folder = os.path.join(keep, wp.config.version, meta[: -len(".meta")])
        shutil.copytree(d, folder, dirs_exist_ok=True)
print(json.dumps({"seconds": seconds}))
"""

_LIST = """
import json, warp as wp
wp.config.quiet = True
from warptex.kernels import all_kernels
print(json.dumps(sorted({k.module.name for k in all_kernels()})))
"""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arch", type=int, default=90, help="the sm architecture (default: %(default)s)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="modules compiled at once (default: every core)")
    p.add_argument("--keep", metavar="DIR", help="keep the compiled modules in DIR, laid out as Warp's kernel cache (WARP_CACHE_PATH=DIR on a GPU "
                                                 "machine then loads them instead of compiling; benchmarks/device_checks.sh)")  # fmt: skip
    args = p.parse_args(argv)
    keep = [os.path.abspath(args.keep)] if args.keep else []
    with tempfile.TemporaryDirectory(prefix="warptex_aot_") as tmp:
        env = {**os.environ, "WARP_CACHE_PATH": os.path.join(tmp, "cache")}
        listed = subprocess.run([sys.executable, "-c", _LIST], env=env, capture_output=True, text=True, check=True)
        modules = json.loads(listed.stdout.strip().splitlines()[-1])
        script = os.path.join(tmp, "compile_one.py")  # Warp reads kernel source from files, not from -c
        with open(script, "w") as f:
            f.write(_CHILD)

        def compile_one(name: str):
            started = time.perf_counter()
            cache = os.path.join(tmp, "cache_" + name)
            result = subprocess.run([sys.executable, script, name, str(args.arch), *keep], env={**env, "WARP_CACHE_PATH": cache}, capture_output=True, text=True, cwd=tmp)
            return name, result, time.perf_counter() - started

        failed = []
        with ThreadPoolExecutor(max(1, args.jobs)) as pool:
            for name, result, wall in pool.map(compile_one, modules):
                if result.returncode != 0:
                    failed.append(name)
                    print(f"compile_cuda: {name}: FAILED\n{result.stderr[-3000:]}", flush=True)
                    continue
                seconds = json.loads(result.stdout.strip().splitlines()[-1])["seconds"]
                print(f"compile_cuda: {name:40s} sm_{args.arch} {seconds:6.1f} s", flush=True)
    print(f"compile_cuda: {len(modules) - len(failed)} of {len(modules)} modules compiled for sm_{args.arch}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
