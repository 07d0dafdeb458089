"""Samples per second of every warptex technique, against the peers a user would pick instead.

For each technique the script times warptex forward and forward+backward (gradients of the sum
of the output to every texel of every mip level), on 1, 2, 4, ... CPU threads up to all of them
(``--thread-counts`` picks others, e.g. more threads than cores to see what the per-thread
gradient copies cost), then the
peers in the same process on the same data (``benchmarks/peers``: vectorised NumPy, PyTorch built
on ``grid_sample``, Dr.Jit's ``Texture2f`` on its LLVM backend; each skipped with its reason when
not installed), and checks that every peer computes what warptex computes (max abs difference).
``triplanar_aniso`` is triplanar with the anisotropic filter: no peer has one, so compare its rows
with warptex's trilinear ``triplanar`` on the same scene.

Scenes: the orthographic unit sphere (positions × 4 as triplanar coordinates; sample techniques
read the Z projection's UV and derivatives), the default terrain from its default camera, and
random UVs. Figures: Msamples/s = shaded (covered) pixels or UVs per second; nominal taps/s =
Msamples/s × the texel reads a sample makes at most (trilinear reads 8; zero-weight projections,
layers and stochastic taps are skipped, so real reads are fewer).

Every figure of a row (warptex at each thread count, each peer, each pass) is timed in the same
``--repeats`` interleaved rounds, and is the fastest of its rounds. A round takes every figure in
turn: a 50 ms pause (Dr.Jit's and torch's thread pools spin for up to ~25 ms after a call and would
take a core from the next), one untimed call (it wakes the pool and refills the caches the previous
figure took), then one timed call. Interleaving gives every figure the same share of the host's
drift; on a shared host the same code's time moves by 2x over seconds, and figures timed one after
another would put that drift into their ratio.

    python benchmarks/bench_samplers.py                      # full run, writes bench_out/
    python benchmarks/bench_samplers.py --quick --json r.json
    python benchmarks/bench_samplers.py --device cuda:0      # on a GPU: torch and Dr.Jit on CUDA too
    python benchmarks/bench_samplers.py --call-cost          # what a small call costs, against torch

``--formats float32 unorm8 float16`` adds rows of warptex reading its textures (and splat layers) in
those texel formats (``warptex.Format``), timed in the same interleaved rounds as float32's: the
same techniques on compact texels. Splat maps stay float32. A format's texels are its encoding of
the float32 texture's, so its outputs differ from the peers' by that rounding. Peers that store half
textures natively add float16 rows compared with warptex's float16 rows: Dr.Jit's ``Texture2f16``
(the CPU and CUDA), torch's half tensors (CUDA only: its CPU half ``grid_sample`` is broken, see
``peers/torch_peer.py``).

``--limit`` times a yardstick beside the peers: a plain C loop of the bilinear lookup
(``peers/limit_peer.py``), compiled at run time with the system's C compiler (``-O3 -march=native
-fopenmp``) and skipped, with the reason, without one. It is the hardware's pace, not a peer. It
also reports the memory the run gets: how long one load waits over working sets of 1 to 128 MB (a
pointer chase), where that cache ends, and the texture's size in each format. At random UVs that,
not the L3 the CPU reports, decides whether texels come from cache.

``--atomics`` (CUDA) adds a forward+backward row of warptex with its texel gradients added by
float atomics (``set_deterministic_gradients(False)``), in the same interleaved rounds as the
default fixed-point sums, the same bits every run: what that determinism costs on the device.

``--uv-grads`` (bilinear and trilinear) makes every forward+backward take the UVs' gradients as
well as the texels' (``warptex.sample`` with a UV array that requires them; ``grid_sample``'s grid
gradient in torch; Dr.Jit's AD through the texture lookup's position): the differentiable
renderer's view, where the UVs move.

``--runs 3`` times every row in 3 runs of ``--repeats`` interleaved rounds. Each figure is still
the fastest call of all; each ratio in the summaries becomes its spread over the runs (the lowest
and highest of the runs' ratios), so a ratio that swings across a bar between runs shows it.

``--processes 3`` runs all of that in 3 fresh processes, one after another, and gives each ratio's
spread over every run of every process. A peer's pace can differ from one process to the next
while warptex's does not, and the rounds of one process never show that; the fresh processes do.
(Dr.Jit's did, by up to 1.6x, while its peer took NumPy's arrays wherever they happened to start:
peers/drjit_peer.py.)

``--call-cost`` times what a call costs when it computes little: ``sample`` (bilinear, a 256² RGBA
texture) on 1, 1,024 and 65,536 random UVs, into a new output and into ``out=``, and through the
PyTorch bridge (``warptex.torch.sample`` on tensors), forward and forward+backward (gradients to
every texel), against torch ``grid_sample`` on the same data (a UV array or tensor kept between
calls, as a loop keeps it; and, forward, ``new uv``: a new UV array each call, a Warp view of the
same data as ``wp.from_torch`` makes of a new tensor, into a new output); and ``triplanar``,
``biplanar`` and ``splat`` (four layers of that texture) over a 1-pixel G-buffer. Each figure is
the median of many calls, taken in interleaved rounds.

On a CUDA device, warptex runs one launch per call (no CPU threads), the peers are torch on the same
device and Dr.Jit's CUDA backend (NumPy is skipped), and every timed call ends by waiting for the GPU.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import trimesh
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import peers  # noqa: E402  (benchmarks/peers, next to this file)
from peers import common  # noqa: E402

import warptex as wt  # noqa: E402
from warptex.formats import TEXEL_BYTES  # noqa: E402
from warptex.plot import line_chart  # noqa: E402
from warptex.scenes import TERRAIN_GRID, terrain_camera  # noqa: E402
from warptex.scenes.terrain import terrain  # noqa: E402
from warptex.scenes.material import noise_texture, terrain_splat_maps  # noqa: E402

# triplanar_aniso: triplanar with the anisotropic filter, against warptex's own trilinear triplanar
# (no peer filters anisotropically).
TECHNIQUES = (*peers.TECHNIQUES, "triplanar_aniso")
SAMPLE_TECHNIQUES = ("bilinear", "trilinear", "hash4", "cheap2", "hex")
# Texel reads per sample at most (trilinear: 8 per read). Splat: one bilinear map read per 4 layers.
NOMINAL_TAPS = {"bilinear": 4, "trilinear": 8, "hash4": 32, "cheap2": 16, "hex": 24, "triplanar": 24, "triplanar_aniso": 24, "biplanar": 16, "triplanar_normal": 24, "splat4": 4 + 4 * 8, "splat8": 8 + 8 * 8}
SPHERE_TILING = 4.0


# -- scenes -------------------------------------------------------------------------------------------


def texture(size: int, channels: int = 4, seed: int = 0, device=None) -> wt.Texture:
    """A seeded ``size²`` noise texture (RGBA: three noise channels and a fourth for height)."""
    rgb = noise_texture(size, seed=seed)
    extra = noise_texture(size, seed=seed + 1)[..., :1]
    return wt.Texture(np.concatenate([rgb, extra], -1)[..., :channels], device=device)


def sphere(resolution: int, device=None) -> wt.GBuffer:
    mesh = trimesh.creation.icosphere(subdivisions=6)
    mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.vertices[:, :2] * 0.5 + 0.5)
    return wt.rasterize(mesh, wt.orthographic((0, 0, 3), (0, 0, 0), height=2.0, resolution=(resolution, resolution)), device=device)


def terrain_mesh(cache: dict):
    """The default terrain mesh, built once per run."""
    if "terrain_mesh" not in cache:
        cache["terrain_mesh"] = terrain(resolution=TERRAIN_GRID, seed=0)
    return cache["terrain_mesh"]


def scene_data(technique: str, scene: str, size: dict, tex: wt.Texture, cache: dict, device=None) -> tuple[dict, dict]:
    """``(data, warptex objects)`` of ``technique`` on ``scene`` (see :mod:`peers.common`)."""
    if scene == "random":
        rng = np.random.default_rng(7)
        n = size["random"]
        uv = rng.uniform(0, 8, (n, 2)).astype(np.float32)
        lod = None if technique == "bilinear" else rng.uniform(0, 4, n).astype(np.float32)
        return common.sample_data(tex, uv, lod=lod), {"texture": tex}
    if scene not in cache:
        cache[scene] = sphere(size["sphere"], device) if scene == "sphere" else wt.rasterize(terrain_mesh(cache), terrain_camera((size["terrain"],) * 2), device=device)
    g = cache[scene]
    scale = SPHERE_TILING if scene == "sphere" else 1.0 / 6.0
    if technique in SAMPLE_TECHNIQUES:  # the Z projection's UVs over the covered pixels
        arrays = g.numpy()
        covered = arrays["mask"].reshape(-1) > 0
        uv, dx, dy = (arrays[k].reshape(-1, 3)[covered][:, :2] * scale for k in ("position", "position_dx", "position_dy"))
        kw = {} if technique == "bilinear" else {"uv_dx": dx, "uv_dy": dy}
        return common.sample_data(tex, uv, **kw), {"texture": tex}
    if technique in common.SPLAT_LAYERS:
        count = common.SPLAT_LAYERS[technique]
        key = ("layers", count)
        if key not in cache:
            levels = np.stack([texture(tex.width, seed=10 + j).numpy() for j in range(count)])
            cache[key] = wt.TextureArray(levels, device=device)
        if scene == "terrain" and count == 4:  # the terrain's own height/slope splat map
            maps = wt.TextureArray(terrain_splat_maps(terrain_mesh(cache), TERRAIN_GRID)[None], mipmaps=False, device=device)
        else:
            maps = wt.TextureArray(np.random.default_rng(count).random((count // 4, 64, 64, 4)).astype(np.float32), mipmaps=False, device=device)
        tiling = (np.arange(count, dtype=np.float32) % 4 + 2.0) * (8.0 if scene == "sphere" else 4.0)
        data = common.gbuffer_data(g, layers=cache[key], maps=maps, tiling=tiling)
        return data, {"gbuffer": g, "layers": cache[key], "maps": maps}
    data = common.gbuffer_data(g, texture=tex, tiling=scale)
    return data, {"gbuffer": g, "texture": tex}


def samples(data: dict) -> int:
    return int((data["mask"] > 0).sum()) if "mask" in data else len(data["uv"])


def rates(technique: str, n: int, seconds: float) -> dict:
    """A figure's rates: samples (millions) and nominal texel taps a second, for ``n`` samples."""
    return {"msamples_per_s": n / seconds / 1e6, "nominal_taps_per_s": n * NOMINAL_TAPS[technique] / seconds}


# -- timing -------------------------------------------------------------------------------------------


PAUSE_S = 0.05  # before each timed figure of a round: longer than the peers' pools spin after a call


def interleaved_best(runs: dict, repeats: int, pause: float = PAUSE_S) -> dict:
    """Seconds of the fastest call of each of ``runs``, timed in ``repeats`` interleaved rounds.

    ``runs`` maps a name to ``(run, sync, setup)``. Each round takes every entry in turn: sleep
    ``pause`` seconds, ``setup()`` (e.g. warptex's thread count), one untimed call, then one timed
    call; both calls end with ``sync()``, which waits for work queued on a GPU. The first round's
    untimed call also compiles and allocates.
    """
    best = dict.fromkeys(runs, float("inf"))
    for _ in range(repeats):
        for name, (run, sync, setup) in runs.items():
            time.sleep(pause)
            setup()
            run()
            sync()
            t = time.perf_counter()
            run()
            sync()
            best[name] = min(best[name], time.perf_counter() - t)
    return best


def _nothing() -> None:
    pass


def in_format(t, fmt: str):
    """Texture ``t`` with its level 0 stored in ``fmt`` (float32: ``t`` itself); compact formats
    build their own mips from it."""
    if fmt == "float32":
        return t
    return type(t)(t.numpy(0), format=fmt, mipmaps=t.num_levels > 1, device=t.device)


def warptex_runs(technique: str, data: dict, objs: dict, device=None, fmt: str = "float32"):
    """``(forward, forward_backward)`` callables of warptex for ``technique``, its textures (not
    splat maps) stored in ``fmt``; with ``data["uv_grads"]``, forward_backward takes the UVs'
    gradients too."""
    objs = {k: in_format(v, fmt) if k in ("texture", "layers") else v for k, v in objs.items()}

    # Inputs as Warp arrays up front, as the peers convert theirs in prepare(), untimed.
    data = dict(data)
    for key, dtype in (("uv", wp.vec2), ("uv_dx", wp.vec2), ("uv_dy", wp.vec2), ("lod", float)):
        if key in data and technique in SAMPLE_TECHNIQUES:
            data[key] = wp.array(data[key], dtype=dtype, device=device)

    def forward():
        return common.warptex_forward(technique, data, device=device, **objs)

    # The same texels with gradient buffers; every level is a leaf (the chain is not rebuilt on the tape).
    grad_objs = {k: with_grad(v) if k in ("texture", "layers", "maps") else v for k, v in objs.items()}
    grad_data = dict(data)
    if common.uv_grads(data):
        grad_data["uv"] = wp.array(data["uv"].numpy(), dtype=wp.vec2, device=device, requires_grad=True)

    def forward_backward():
        for key in ("texture", "layers", "maps"):
            if key in grad_objs:
                grad_objs[key].zero_grad()
        if common.uv_grads(data):
            grad_data["uv"].grad.zero_()
        tape = wp.Tape()
        with tape:
            out = common.warptex_forward(technique, grad_data, device=device, **grad_objs)
        out.grad.fill_(1.0)
        tape.backward()
        return out

    return forward, forward_backward


def with_grad(t):
    """A copy of texture ``t`` (same texels and format, same mip chain) that receives gradients."""
    level0 = t.numpy(0)
    return type(t)(level0, format=t.format, mipmaps=t.num_levels > 1, requires_grad=True, device=t.device)


def measure_technique(technique: str, scene: str, args, tex, cache, backends: dict, report) -> list[dict]:
    """Time warptex and the peers on one technique and scene; print and return the records."""
    data, objs = scene_data(technique, scene, args.sizes, tex, cache, args.device)
    if args.uv_grads:
        data["uv_grads"] = True
    n = samples(data)
    records = []
    cuda = wp.get_device(args.device).is_cuda

    def record(impl, pass_, threads, seconds, **extra):
        rec = {"technique": technique, "scene": scene, "impl": impl, "pass": pass_, "device": args.device, "threads": threads, "seconds": seconds, "samples": n,
               **rates(technique, n, seconds), **extra}  # fmt: skip
        if args.uv_grads and pass_ == "forward+backward":
            rec["uv_grads"] = True
        records.append(rec)
        return rec

    forward, forward_backward = warptex_runs(technique, data, objs, args.device)
    runs, reference = {}, {}
    thread_counts = [None] if cuda else args.thread_counts  # a CUDA launch fills the device
    for threads in thread_counts:
        wt.set_num_threads(threads)
        out = forward().numpy()
        reference[threads] = out.reshape(-1, out.shape[-1])
        setup = lambda threads=threads: (wt.set_num_threads(threads), wt.set_deterministic_gradients(True))
        runs["warptex", "forward", threads] = (forward, wp.synchronize, setup)
        runs["warptex", "forward+backward", threads] = (forward_backward, wp.synchronize, setup)
    extras = {}
    if getattr(args, "atomics", False):  # CUDA: texel gradients added with float atomics, against the fixed-point sums above
        runs["warptex atomics", "forward+backward", None] = (forward_backward, wp.synchronize, lambda: wt.set_deterministic_gradients(False))
        extras["warptex atomics", "forward+backward", None] = {"gradients": "float atomics"}
    peer_threads = None if cuda else args.threads
    compact_out = {}
    for fmt in args.formats:  # compact texels, on the peers' thread count
        if fmt == "float32":
            continue
        impl, setup = f"warptex {fmt}", (lambda: (wt.set_num_threads(peer_threads), wt.set_deterministic_gradients(True)))
        setup()
        compact, compact_backward = warptex_runs(technique, data, objs, args.device, fmt)
        compact_out[fmt] = out = compact().numpy().reshape(reference[peer_threads].shape)
        extras[impl, "forward", peer_threads] = {"format": fmt, "max_abs_diff": float(np.nanmax(np.abs(out - reference[peer_threads]))) if out.size else 0.0}
        runs[impl, "forward", peer_threads] = (compact, wp.synchronize, setup)
        try:
            compact_backward()
        except ValueError as err:  # a gradient only Warp's generated adjoint takes: float32 textures only
            report(f"  {impl} forward+backward: skipped ({err})")
        else:
            extras[impl, "forward+backward", peer_threads] = {"format": fmt}
            runs[impl, "forward+backward", peer_threads] = (compact_backward, wp.synchronize, setup)
    single_vs_all = max((float(np.nanmax(np.abs(r - reference[thread_counts[0]]))) if r.size else 0.0) for r in reference.values())

    def covered(out):
        return out[data["mask"] > 0] if "mask" in data and out.shape[0] == data["mask"].shape[0] else out

    for backend, table in backends.items():
        peer = table.get(technique)
        if peer is None:
            continue
        if not cuda:
            peers.set_threads(backend, args.threads)
        sync = lambda backend=backend: peers.synchronize(backend)  # noqa: E731
        # float32, and the compact formats the peer stores natively (compared with warptex's rows of that format)
        for fmt in ["float32", *(f for f in compact_out if f in peer.formats)]:
            impl = backend if fmt == "float32" else f"{backend} {fmt}"
            tag = {} if fmt == "float32" else {"format": fmt}
            try:
                state = peer.prepare(data if fmt == "float32" else {**data, "format": fmt})
                got = covered(np.asarray(peer.output(peer.forward(state)), np.float32))
                expected = covered(reference[peer_threads] if fmt == "float32" else compact_out[fmt])
                diff = float(np.nanmax(np.abs(got - expected))) if got.size else 0.0
                runs[impl, "forward", peer_threads] = (lambda peer=peer, state=state: peer.forward(state), sync, _nothing)
                extras[impl, "forward", peer_threads] = {"max_abs_diff": diff, "note": peer.note, **tag}
                if peer.forward_backward is not None:
                    peer.forward_backward(state)  # a peer that cannot hold the gradients fails here, untimed
                    runs[impl, "forward+backward", peer_threads] = (lambda peer=peer, state=state: peer.forward_backward(state), sync, _nothing)
                    extras[impl, "forward+backward", peer_threads] = {"note": peer.note, **tag}
            except MemoryError as err:  # a peer that cannot hold the scene is reported, not fatal
                report(f"  {impl}: skipped ({err})")
                for key in [k for k in runs if k[0] == impl]:
                    del runs[key]
    try:
        per_run = [interleaved_best(runs, args.repeats) for _ in range(args.runs)]
    finally:
        wt.set_deterministic_gradients(True)
    for key in runs:
        spread = {"run_seconds": [r[key] for r in per_run]} if args.runs > 1 else {}
        record(*key, min(r[key] for r in per_run), **extras.get(key, {}), **spread)
    wt.set_num_threads(peer_threads)
    report(format_rows(records, single_vs_all))
    for rec in records:
        rec["threaded_max_abs_diff"] = single_vs_all
    return records


def format_thread_scaling(records: list[dict]) -> str:
    """warptex's speed-up over one thread at each thread count, forward and forward+backward, one
    line per technique and scene ("" on a GPU, or with one thread count)."""
    times = {}
    for r in records:
        if r["impl"] == "warptex" and r["threads"] is not None:
            times.setdefault((r["technique"], r["scene"]), {}).setdefault(r["pass"], {})[r["threads"]] = r["seconds"]
    counts = sorted({t for by_pass in times.values() for runs in by_pass.values() for t in runs})
    if len(counts) < 2 or 1 not in counts:
        return ""
    lines = ["thread scaling (speed-up over 1 thread): " + ", ".join(f"{t} thr" for t in counts[1:])]
    for (technique, scene), by_pass in times.items():
        cells = [f"{p} " + " ".join(f"{runs[1] / runs[t]:5.2f}" for t in counts[1:]) for p, runs in by_pass.items()]
        lines.append(f"  {technique:16s} {scene:8s} " + "   ".join(cells))
    return "\n".join(lines)


def base_impl(record: dict) -> str:
    """The warptex row a record is compared with: warptex in the record's texel format."""
    return f"warptex {record['format']}" if "format" in record and not record["impl"].startswith("warptex") else "warptex"


def ratio_cell(num: dict | None, den: dict | None) -> str:
    """``num``'s time over ``den``'s: the ratio of their best times, or, where both were timed in
    several runs (``--runs``), the spread of the runs' ratios, ``min–max``."""
    if num is None or den is None:
        return "  -  "
    if "run_seconds" in num and "run_seconds" in den:
        ratios = [a / b for a, b in zip(num["run_seconds"], den["run_seconds"])]
        return f"{min(ratios):.2f}–{max(ratios):.2f}"
    return f"{num['seconds'] / den['seconds']:5.2f}"


def format_peer_summary(records: list[dict]) -> str:
    """One table of every technique and scene: warptex's forward and forward+backward times on the
    peers' thread count, and each peer's time over warptex's in the same run (below 1: the peer
    is faster; a peer's float16 row over warptex's float16 row); "" without peers."""
    impls = sorted({r["impl"] for r in records if not r["impl"].startswith("warptex")})
    if not impls:
        return ""
    peer_threads = {(r["technique"], r["scene"]): r["threads"] for r in records if not r["impl"].startswith("warptex")}
    rec = {(r["technique"], r["scene"], r["impl"], r["pass"]): r for r in records if r["threads"] == peer_threads.get((r["technique"], r["scene"]), "none")}
    bases = {r["impl"]: base_impl(r) for r in records}
    rows = []
    for technique, scene in peer_threads:
        base = [rec.get((technique, scene, "warptex", p)) for p in ("forward", "forward+backward")]
        if None in base:
            continue
        cells = []
        for impl in impls:
            pair = [(rec.get((technique, scene, impl, p)), rec.get((technique, scene, bases.get(impl, "warptex"), p))) for p in ("forward", "forward+backward")]
            cells.append(" / ".join(ratio_cell(a, b) for a, b in pair))
        rows.append((f"  {technique:16s} {scene:8s} {base[0]['seconds'] * 1e3:7.1f} / {base[1]['seconds'] * 1e3:7.1f}  ", cells))
    width = max([13, *(len(i) for i in impls), *(len(c) for _, cells in rows for c in cells)])
    grads = " (gradients of the texels and the UVs: --uv-grads)" if any(r.get("uv_grads") for r in records) else ""
    lines = [f"peers against warptex (peer time ÷ warptex time, same run; below 1: the peer is faster), forward / forward+backward{grads}:",
             f"  {'technique':16s} {'scene':8s} {'warptex ms':>17s}  " + "  ".join(f"{impl:>{width}s}" for impl in impls)]  # fmt: skip
    lines += [head + "  ".join(f"{c:>{width}s}" for c in cells) for head, cells in rows]
    return "\n".join(lines)


def format_format_summary(records: list[dict]) -> str:
    """Each compact format's speed-up over float32 textures (float32 time ÷ format time, same run;
    above 1: the format is faster), forward / forward+backward; "" without ``--formats``."""
    formats = sorted({r["format"] for r in records if "format" in r})
    if not formats:
        return ""
    rec = {(r["technique"], r["scene"], r.get("format", "float32"), r["pass"], r["threads"]): r for r in records if r["impl"].startswith("warptex") and "gradients" not in r}
    rows = sorted({(r["technique"], r["scene"], r["threads"]) for r in records if "format" in r}, key=lambda k: (k[0], k[1]))
    table = []
    for technique, scene, threads in rows:
        cells = []
        for f in formats:
            pair = [(rec.get((technique, scene, "float32", p, threads)), rec.get((technique, scene, f, p, threads))) for p in ("forward", "forward+backward")]
            cells.append(" / ".join(ratio_cell(a, b) for a, b in pair))
        table.append((f"  {technique:16s} {scene:8s} ", cells))
    width = max([13, *(len(c) for _, cells in table for c in cells)])
    lines = ["texel formats against float32 (float32 time ÷ format time, same run; above 1: faster), forward / forward+backward:",
             f"  {'technique':16s} {'scene':8s} " + "  ".join(f"{f:>{width}s}" for f in formats)]  # fmt: skip
    lines += [head + "  ".join(f"{c:>{width}s}" for c in cells) for head, cells in table]
    return "\n".join(lines)


def format_rows(records: list[dict], threaded_diff: float) -> str:
    """One block per technique: each implementation's figures and its time ratio to warptex."""
    first = records[0]
    base = {(r["impl"], r["pass"], r["threads"]): r["seconds"] for r in records if r["impl"].startswith("warptex")}
    threaded = "" if first["threads"] is None else f"; threaded vs 1 thread max diff {threaded_diff:.1e}"
    lines = [f"{first['technique']} on {first['scene']} ({first['samples']:,} samples on {first['device']}{threaded})"]
    for r in records:
        ratio = r["seconds"] / base[(base_impl(r), r["pass"], r["threads"])]
        diff = f"  diff {r['max_abs_diff']:.1e}" if "max_abs_diff" in r else ""
        where = "  GPU " if r["threads"] is None else f"{r['threads']:2d} thr"
        lines.append(
            f"  {r['impl']:14s} {r['pass']:16s} {where}  {r['seconds'] * 1e3:9.2f} ms  {r['msamples_per_s']:8.2f} Ms/s  "
            f"{r['nominal_taps_per_s'] / 1e9:6.2f} Gtap/s  {'x' + format(ratio, '.2f') + ' ' + base_impl(r) + ' time' if r['impl'] != 'warptex' else ''}{diff}"
        )
    return "\n".join(lines)


# -- scaling ------------------------------------------------------------------------------------------


def scaling(args, backends: dict, report) -> dict:
    """Triplanar forward (all threads) against pixel count and texture size; peers where available."""
    out = {"pixels": {}, "texture": {}}
    tex = texture(1024 if not args.quick else 256, device=args.device)
    for res in args.scaling_pixels:
        g = sphere(res, args.device)
        data = common.gbuffer_data(g, texture=tex, tiling=SPHERE_TILING)
        runs = {"warptex": (lambda g=g: wt.triplanar(g, tex, tiling=SPHERE_TILING), wp.synchronize, _nothing)}
        for backend, table in backends.items():
            peer = table.get("triplanar")
            if peer is not None:
                state = peer.prepare(data)
                runs[backend] = (lambda peer=peer, state=state: peer.forward(state), lambda backend=backend: peers.synchronize(backend), _nothing)
        out["pixels"][res] = row = interleaved_best(runs, args.repeats)
        report(f"  pixels {res}²: " + "  ".join(f"{k} {v * 1e3:.1f} ms" for k, v in row.items()))
    g = sphere(args.scaling_pixels[len(args.scaling_pixels) // 2], args.device)
    for size in args.scaling_textures:
        t = texture(size, device=args.device)
        out["texture"][size] = interleaved_best({"warptex": (lambda t=t: wt.triplanar(g, t, tiling=SPHERE_TILING), wp.synchronize, _nothing)}, args.repeats)
        report(f"  texture {size}²: warptex {out['texture'][size]['warptex'] * 1e3:.1f} ms")
    return out


def plot_scaling(path: Path, result: dict, threads: int) -> None:
    pixels = result["pixels"]
    impls = sorted({k for row in pixels.values() for k in row}, key=lambda k: (k != "warptex", k))
    series = {k: ([r * r for r in pixels], [pixels[r].get(k) for r in pixels]) for k in impls}
    tex = result["texture"]
    line_chart(
        path,
        [
            {"series": {k: (x, [None if v is None else v * 1e3 for v in y]) for k, (x, y) in series.items()}, "xlabel": "pixels", "ylabel": "ms",
             "title": f"triplanar forward vs pixel count ({threads if isinstance(threads, str) else f'{threads} threads'})", "logx": True, "logy": True},
            {"series": {"warptex": ([s * s for s in tex], [tex[s]["warptex"] * 1e3 for s in tex])}, "xlabel": "texels (level 0)", "ylabel": "ms",
             "title": "triplanar forward vs texture size", "logx": True,
             "note": "flat: trilinear reads the mip levels that match the pixel footprint, whatever the size"},
        ],
    )  # fmt: skip


# -- main ---------------------------------------------------------------------------------------------


CALL_SAMPLES = (1, 1024, 65536)


def call_cost(args, report) -> list[dict]:
    """Median seconds per call of ``sample`` and torch ``grid_sample`` (module docstring)."""
    import torch

    import warptex.torch as wtt

    device = wp.get_device(args.device)
    torch_device = "cuda" if device.is_cuda else "cpu"
    if device.is_cuda:
        torch.cuda.set_device(device.ordinal)
    rng = np.random.default_rng(0)
    image = rng.random((256, 256, 4), dtype=np.float32)
    tex = wt.Texture(image, mipmaps=False, requires_grad=True, device=device)
    # grid_sample's y = -1 is the image's first (top) row; warptex's v = 0 its bottom one
    timg = torch.tensor(image, device=torch_device).permute(2, 0, 1)[None].contiguous().requires_grad_(True)
    ttex = torch.tensor(image, device=torch_device, requires_grad=True)  # the bridge's [H, W, C] texture
    sampler = wt.Sampler(filter="bilinear", address="clamp")

    def sync() -> None:
        if device.is_cuda:
            wp.synchronize_device(device)
            torch.cuda.synchronize()

    rows = []
    for n in CALL_SAMPLES:
        uv_np = rng.random((n, 2), dtype=np.float32)
        uv = wp.array(uv_np, dtype=wp.vec2, device=device)
        out = wp.empty((n, 4), dtype=wp.float32, device=device, requires_grad=True)
        grid = torch.tensor(uv_np * [2, -2] + [-1, 1], device=torch_device, dtype=torch.float32).reshape(1, 1, n, 2)
        weights = wp.ones((n, 4), dtype=wp.float32, device=device)

        def ours_backward(into=None):
            tape = wp.Tape()
            with tape:
                result = wt.sample(tex, uv, sampler=sampler, out=into)
            tape.backward(grads={result: weights})
            tape.zero()

        def torch_forward():
            with torch.no_grad():
                return torch.nn.functional.grid_sample(timg, grid, mode="bilinear", padding_mode="border", align_corners=False)

        def torch_backward():
            timg.grad = None
            torch.nn.functional.grid_sample(timg, grid, mode="bilinear", padding_mode="border", align_corners=False).sum().backward()

        tuv = torch.tensor(uv_np, device=torch_device)

        def bridge_forward():
            with torch.no_grad():
                return wtt.sample(ttex, tuv, sampler=sampler)

        def bridge_backward():
            ttex.grad = None
            wtt.sample(ttex, tuv, sampler=sampler).sum().backward()

        with torch.no_grad():
            ours, theirs = wt.sample(tex, uv, sampler=sampler).numpy(), torch_forward()[0, :, 0].T.cpu().numpy()
        diff = float(np.abs(ours - theirs).max())
        bridged = float(np.abs(bridge_forward().cpu().numpy() - ours).max())

        def new_uv():
            return wt.sample(tex, wp.array(ptr=uv.ptr, dtype=wp.vec2, shape=uv.shape, device=device), sampler=sampler)

        renewed = max(float(np.abs(new_uv().numpy() - ours).max()) for _ in range(3))  # (from the third call, a kept plan's)
        figures = {
            ("forward", "warptex"): lambda: wt.sample(tex, uv, sampler=sampler),
            ("forward", "warptex out="): lambda: wt.sample(tex, uv, sampler=sampler, out=out),
            ("forward", "warptex new uv"): new_uv,
            ("forward", "warptex.torch"): bridge_forward,
            ("forward", "torch"): torch_forward,
            ("forward+backward", "warptex"): ours_backward,
            ("forward+backward", "warptex out="): lambda: ours_backward(out),
            ("forward+backward", "warptex.torch"): bridge_backward,
            ("forward+backward", "torch"): torch_backward,
        }
        median = interleaved_median(figures, sync, rounds=args.repeats, calls=args.calls)
        for (pass_, impl), seconds in median.items():
            rows.append({"technique": "sample", "samples": n, "pass": pass_, "impl": impl, "seconds": seconds,
                         "max_abs_diff": {"torch": diff, "warptex.torch": bridged, "warptex new uv": renewed}.get(impl, 0.0)})  # fmt: skip
    report(format_call_cost(rows))
    report(f"max |warptex - torch| over the outputs: {max(r['max_abs_diff'] for r in rows):.2e}")
    rows += _one_pixel_projections(args, tex, sync, report)
    return rows


def _one_pixel_projections(args, tex, sync, report) -> list[dict]:
    """Forward calls of ``triplanar``, ``biplanar`` and ``splat`` (four layers of ``tex``, world_xz)
    over a 1-pixel G-buffer, into a new output and into ``out=`` (no peer computes this)."""
    g = wt.GBuffer.empty((1, 1), uv_sets=("uv0",), device=tex.device)
    g.position.assign(np.float32([[[0.3, 0.7, 0.2]]]))
    g.normal.assign(np.float32([[[0.3, 0.8, 0.5]]]))
    g.uv_sets["uv0"]["uv"].assign(np.float32([[[0.4, 0.6]]]))
    g.mask.fill_(1)
    out = wp.empty((1, 1, 4), dtype=wp.float32, device=tex.device)
    layers = wt.TextureArray([tex] * 4, device=tex.device)
    maps = wt.TextureArray(np.full((1, 4, 4, 4), 0.25, np.float32), mipmaps=False, device=tex.device)
    calls = {"triplanar": lambda into: wt.triplanar(g, tex, tiling=2.0, out=into), "biplanar": lambda into: wt.biplanar(g, tex, tiling=2.0, out=into),
             "splat": lambda into: wt.splat(g, layers, maps, tiling=2.0, projection="world_xz", out=into)}  # fmt: skip
    figures = {(f, into): (lambda f=f, into=into: calls[f](out if into else None)) for f in calls for into in (False, True)}
    median = interleaved_median(figures, sync, rounds=args.repeats, calls=args.calls)
    rows = [{"technique": f, "samples": 1, "pass": "forward", "impl": "warptex out=" if into else "warptex", "seconds": s, "max_abs_diff": 0.0} for (f, into), s in median.items()]
    report("1-pixel calls (median us): " + ", ".join(f"{r['technique']} {r['impl']} {r['seconds'] * 1e6:.1f}" for r in rows))
    return rows


def interleaved_median(figures: dict, sync, rounds: int, calls: int) -> dict:
    """Median seconds per call of each of ``figures`` (``{key: call}``): ``rounds`` rounds, each
    giving every figure in turn a few untimed calls, then ``calls`` timed one by one."""
    times = {key: [] for key in figures}
    for _ in range(rounds):
        for key, call in figures.items():
            for _ in range(3):
                call()
            sync()
            for _ in range(calls):
                t = time.perf_counter()
                call()
                sync()
                times[key].append(time.perf_counter() - t)
    return {key: float(np.median(ts)) for key, ts in times.items()}


def format_call_cost(rows: list[dict]) -> str:
    """The call-cost table: microseconds per call, and each warptex figure over torch's."""
    ours = ("warptex", "warptex out=", "warptex new uv", "warptex.torch")
    lines = ["call cost (median us per call; warptex / torch in brackets):", f"{'samples':>8} {'pass':<17} " + " ".join(f"{i:>16}" for i in ours) + f" {'torch':>9}"]
    for n in CALL_SAMPLES:
        for pass_ in ("forward", "forward+backward"):
            got = {r["impl"]: r["seconds"] for r in rows if r["samples"] == n and r["pass"] == pass_}
            if not got:
                continue
            torch_s = got["torch"]
            cells = [f"{got[i] * 1e6:8.1f} ({got[i] / torch_s:5.2f}x)" if i in got else "" for i in ours]  # (new uv: forward only)
            lines.append(f"{n:>8} {pass_:<17} " + " ".join(f"{c:>16}" for c in cells) + f" {torch_s * 1e6:9.1f}")
    return "\n".join(lines)


def memory_seen(args, report) -> dict:
    """Where the cache this run gets ends (``--limit``: the C loop's pointer chase), reported beside
    the texture's level 0 in each format: at random UVs, texels inside it are read from cache and
    texels past it from DRAM, whatever the CPU's L3 is said to be."""
    from peers import limit_peer

    sizes = [1, 2, 4, 8] if args.quick else [1, 2, 4, 8, 16, 32, 64, 128]
    latency = limit_peer.load_latency(sizes, steps=1 << 18 if args.quick else 1 << 21)
    inside, outside = limit_peer.cache_end(latency)
    report("memory this run gets (a pointer chase, 1 thread; ns per load over N MB): " + " · ".join(f"{mb} MB {ns:.0f}" for mb, ns in latency.items()))
    where = (f"from cache up to {inside} MB" if inside else "from DRAM at every size") + (f", from DRAM from {outside} MB on" if outside and inside else "")
    shown = {"float32": wt.Format.FLOAT32, "float16": wt.Format.FLOAT16, "8 bits": wt.Format.UNORM8}  # srgb8's texels are unorm8's size
    level0 = {name: args.texture_size**2 * TEXEL_BYTES[fmt] / 2**20 for name, fmt in shown.items()}
    report(f"  random reads come {where}; the texture's level 0 is " + ", ".join(f"{mb:g} MB in {name}" for name, mb in level0.items()))
    return {"latency_ns": latency, "cache_inside_mb": inside, "cache_outside_mb": outside, "level0_mb": level0}


def run(args) -> dict:
    wp.config.quiet = True
    wp.init()
    lines = []

    def report(text):
        print(text, flush=True)
        lines.append(text)

    if args.call_cost:
        try:
            import torch  # noqa: F401
        except ImportError:
            report("call cost: skipped (torch is not installed: pip install torch)")
            return {"call_cost": [], "skipped_peers": {"torch": "not installed"}}
        return {"machine": {"platform": platform.platform(), "cpus": wt.get_num_threads(), "device": wp.get_device(args.device).name, "warp": wp.config.version},
                "call_cost": call_cost(args, report)}  # fmt: skip

    backends, skipped = {}, {}
    for backend in args.peers + (["limit"] if args.limit else []):
        try:
            peers.set_device(backend, args.device)
            backends[backend] = peers.load(backend)
        except peers.PeerUnavailable as why:
            skipped[backend] = str(why)
            report(f"peer {backend}: skipped ({why})")
    for fmt in args.formats:
        without = [b for b, table in backends.items() if fmt != "float32" and not any(fmt in peer.formats for peer in table.values())]
        if without:
            report(f"{fmt} rows: none of {', '.join(without)} (not stored natively on {args.device}; peers/<name>_peer.py says why)")
    tex = texture(args.texture_size, device=args.device)
    report(f"texture: {args.texture_size}² RGBA with mips, {tex.nbytes / 2**20:.0f} MB in float32 (--texture-size)")
    memory = memory_seen(args, report) if "limit" in backends else None
    cache, records = {}, []
    for technique in args.techniques:
        scenes = ("sphere", "random") if technique in SAMPLE_TECHNIQUES else ("sphere", "terrain")
        for scene in scenes:
            records += measure_technique(technique, scene, args, tex, cache, backends, report)
    result = {"machine": {"platform": platform.platform(), "cpus": wt.get_num_threads(), "device": wp.get_device(args.device).name, "python": platform.python_version(), "warp": wp.config.version},
              "settings": {k: v for k, v in vars(args).items() if k not in ("json", "out")}, "skipped_peers": skipped, "records": records}  # fmt: skip
    if memory is not None:
        result["memory"] = memory
    if not args.no_scaling:
        report("scaling (triplanar forward):")
        result["scaling"] = scaling(args, backends, report)
        plot_scaling(args.out / "scaling.png", result["scaling"], args.threads if not wp.get_device(args.device).is_cuda else args.device)
        report(f"plot: {args.out / 'scaling.png'}")
    for summary in (format_peer_summary(records), format_format_summary(records), format_thread_scaling(records)):
        if summary:
            report(summary)
    return result


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="small scenes and one repeat (CI)")
    p.add_argument("--json", type=Path, help="write the results here")
    p.add_argument("--out", type=Path, default=Path("bench_out"), help="folder for the scaling plot")
    p.add_argument("--device", default="cpu", help="Warp device: cpu or cuda:N (default: cpu)")
    p.add_argument("--threads", type=int, default=None, help="threads for the all-core figures and the peers (default: every core)")
    p.add_argument("--thread-counts", type=int, nargs="+", default=None, metavar="N",
                   help="warptex's thread counts (default: 1, 2, 4, ... and --threads; --quick: 1 and --threads)")
    p.add_argument("--repeats", type=int, default=None, help="timed runs per figure (default 5, quick 1)")
    p.add_argument("--techniques", nargs="+", default=list(TECHNIQUES), choices=TECHNIQUES)
    p.add_argument("--peers", nargs="*", default=list(peers.BACKENDS), choices=peers.BACKENDS)
    p.add_argument("--limit", action="store_true", help="time a plain C loop of the bilinear lookup beside the peers (peers/limit_peer.py): the hardware's pace; "
                                                          "and report where the cache this run gets ends (a pointer chase)")
    p.add_argument("--runs", type=int, default=1, help="time every row in this many runs of --repeats interleaved rounds; the summaries give each ratio's spread over the runs (min–max)")
    p.add_argument("--processes", type=int, default=1, help="run everything in this many fresh processes, one after another; the summaries give each ratio's "
                                                              "spread over the runs of all of them (the scaling sweeps run in the first only)")
    p.add_argument("--no-scaling", action="store_true", help="skip the pixel-count and texture-size sweeps")
    p.add_argument("--texture-size", type=int, default=None, metavar="N",
                   help="the rows' texture is N x N RGBA (default 1024: 16 MB in float32, 4 MB in 8 bits; 2048: 64 and 16 MB; "
                        "quick 256). Whether they fit the cache this run gets, --limit measures")
    p.add_argument("--formats", nargs="+", default=["float32"], choices=[f.value for f in wt.Format], metavar="FORMAT",
                   help="texel formats of warptex's textures, rows for each (float32 float16 unorm8 srgb8; default float32)")
    p.add_argument("--atomics", action="store_true", help="on CUDA, also time forward+backward with texel gradients added by float atomics "
                                                          "(set_deterministic_gradients(False)) against the default fixed-point sums")  # fmt: skip
    p.add_argument("--uv-grads", action="store_true", help="forward+backward takes the UVs' gradients too, in warptex and the peers (bilinear and trilinear only)")
    p.add_argument("--call-cost", action="store_true", help="only the cost of small calls: sample() (natively and through warptex.torch) on 1, 1,024 and 65,536 UVs against torch")
    p.add_argument("--calls", type=int, default=None, help="--call-cost: timed calls per figure and round (default 200, quick 20)")
    args = p.parse_args(argv)
    wp.config.quiet = True
    wp.init()
    try:
        wp.get_device(args.device)
    except (RuntimeError, ValueError) as err:
        p.error(f"--device {args.device!r}: {err}")
    args.threads = args.threads or wt.get_num_threads()
    if args.threads < 1 or any(n < 1 for n in args.thread_counts or ()):
        p.error("--threads and --thread-counts must be >= 1")
    if args.runs < 1 or args.processes < 1:
        p.error("--runs and --processes must be >= 1")
    if args.processes > 1 and args.call_cost:
        p.error("--call-cost times its calls in one process: leave out --processes")
    if args.uv_grads and set(args.techniques) - {"bilinear", "trilinear"}:
        p.error("--uv-grads times UV gradients of bilinear and trilinear sample(): add --techniques bilinear trilinear")
    if args.atomics and not wp.get_device(args.device).is_cuda:
        p.error("--atomics compares CUDA's fixed-point texel gradients with float atomics; on the CPU they are one path: it needs --device cuda:N")
    doubling = [] if args.quick else [2**k for k in range(1, args.threads.bit_length()) if 2**k < args.threads]
    args.thread_counts = sorted({1, args.threads, *(args.thread_counts if args.thread_counts is not None else doubling)})
    args.repeats = args.repeats or (1 if args.quick else 5)
    args.calls = args.calls or (20 if args.quick else 200)
    args.sizes = {"sphere": 256, "terrain": 128, "random": 1 << 16} if args.quick else {"sphere": 1024, "terrain": 512, "random": 1 << 20}
    if args.texture_size is not None and args.texture_size < 2:
        p.error("--texture-size must be >= 2")
    args.texture_size = args.texture_size or (256 if args.quick else 1024)
    args.scaling_pixels = [64, 128] if args.quick else [256, 512, 1024, 2048]
    args.scaling_textures = [128, 256] if args.quick else [256, 512, 1024, 2048, 4096]
    return args


def _child_argv(argv: list[str], json_path: Path, first: bool) -> list[str]:
    """``argv`` for one of ``--processes``' children: without ``--processes`` and ``--json``, writing
    its results to ``json_path``; the scaling sweeps only in the first."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a in ("--processes", "--json"):
            skip = True
        elif not a.startswith(("--processes=", "--json=")):
            out.append(a)
    return out + ["--json", str(json_path)] + ([] if first or "--no-scaling" in out else ["--no-scaling"])


def merge_processes(results: list[dict]) -> tuple[dict, list[tuple]]:
    """One result of several processes' results (``--processes``): each figure's ``run_seconds`` are
    every process's runs in turn (so the runs of two figures still pair up round by round), its
    ``seconds`` their fastest and its ``max_abs_diff`` the largest. Returns the result and the keys
    (technique, scene, impl, pass, threads) of figures that not every process timed (a peer that
    ran out of memory in one), which are left out."""
    key = lambda r: (r["technique"], r["scene"], r["impl"], r["pass"], r["threads"])  # noqa: E731
    tables = [{key(r): r for r in res["records"]} for res in results]
    records, dropped = [], []
    for k, first in tables[0].items():
        if not all(k in t for t in tables[1:]):
            dropped.append(k)
            continue
        rec = dict(first)
        rec["run_seconds"] = [s for t in tables for s in t[k].get("run_seconds", [t[k]["seconds"]])]
        rec["seconds"] = min(rec["run_seconds"])
        rec.update(rates(rec["technique"], rec["samples"], rec["seconds"]))
        if "max_abs_diff" in rec:
            rec["max_abs_diff"] = max(t[k]["max_abs_diff"] for t in tables)
        records.append(rec)
    dropped += [k for t in tables[1:] for k in t if k not in tables[0]]
    return {**results[0], "records": records, "processes": len(results)}, dropped


def run_processes(args, argv: list[str]) -> dict:
    """``--processes``: the whole run in ``args.processes`` fresh processes, one after another,
    merged (:func:`merge_processes`), and its summaries printed over all of them."""
    import subprocess
    import tempfile

    results = []
    with tempfile.TemporaryDirectory(prefix="bench_samplers_") as tmp:
        for i in range(args.processes):
            print(f"== process {i + 1} of {args.processes}", flush=True)
            path = Path(tmp) / f"p{i}.json"
            done = subprocess.run([sys.executable, str(Path(__file__).resolve()), *_child_argv(argv, path, i == 0)])
            if done.returncode != 0:
                raise SystemExit(f"process {i + 1} of {args.processes} failed (exit {done.returncode})")
            results.append(json.loads(path.read_text()))
    result, dropped = merge_processes(results)
    print(f"== the {args.processes} processes together ({args.runs} run{'s' * (args.runs > 1)} each)")
    for k in dropped:
        print(f"  left out: {' '.join(str(v) for v in k)} (not timed in every process)")
    for summary in (format_peer_summary(result["records"]), format_format_summary(result["records"]), format_thread_scaling(result["records"])):
        if summary:
            print(summary)
    return result


def main(argv=None) -> int:
    args = parse(argv)
    result = run(args) if args.processes == 1 else run_processes(args, list(sys.argv[1:] if argv is None else argv))
    if args.json:
        from warptex.io import _atomic_output

        with _atomic_output(str(args.json)) as tmp:
            Path(tmp).write_text(json.dumps(result, indent=1, default=str))
        print(f"json: {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
