"""CUDA against the CPU: every technique's output and gradients, and the two main jobs on ``cuda:0``.

The kernels are the same source on both devices; these tests check that they compute the same
thing there: outputs to float rounding, gradients to the rounding of atomics summed in another
order. The techniques get one G-buffer, rasterised on the CPU and copied (``GBuffer.to``): the two
rasterisers agree only to rounding (checked on its own here), and on an H100 that rounding, in a
normal or a derivative, moved blend weights and mip levels past these tolerances. Skipped, with
the reason, on a machine without a CUDA device. ``WARPTEX_TEST_DEVICE=cpu`` runs them against the
CPU itself (a check of the tests, where no GPU is at hand). They last ran on an H200 (warp-lang
1.19.0, driver 580, torch 2.11), all passing, on 2026-11-30, through ``benchmarks/device_checks.sh``,
which runs this file on a GPU.
"""

import json
import os
import subprocess
import sys
import weakref

import numpy as np
import pytest
import warp as wp

import reference_triplanar as rt
import warptex as wt
from warptex._warp import paused_tape
from warptex.scenes.terrain import terrain
from warptex.scenes import terrain_camera

OTHER = os.environ.get("WARPTEX_TEST_DEVICE", "cuda:0")
pytestmark = pytest.mark.skipif(OTHER.startswith("cuda") and not wp.is_cuda_available(), reason="no CUDA device: these tests compare CUDA with the CPU")

DEVICES = ("cpu", OTHER)


@pytest.fixture(scope="module")
def scene():
    """Seeded inputs, as NumPy: a terrain G-buffer's mesh and camera, textures, splat maps, UVs."""
    rng = np.random.default_rng(5)
    mesh, camera = terrain(resolution=(65, 65)), terrain_camera((96, 128))
    return {
        "mesh": mesh,
        "camera": camera,
        "gbuffer": wt.rasterize(mesh, camera, device="cpu"),  # the techniques get the same pixels on both devices
        "image": rng.random((48, 40, 4)).astype(np.float32),
        "layers": rng.random((4, 32, 32, 4)).astype(np.float32),
        "maps": rng.random((1, 9, 9, 4)).astype(np.float32) - 0.1,
        "uv": rng.uniform(-3, 3, (5000, 2)).astype(np.float32),
        "lod": rng.uniform(-0.5, 5.0, 5000).astype(np.float32),
        "weights": rng.normal(size=(96, 128, 4)).astype(np.float32),
    }


def _on_both(run):
    """``run(device) -> {name: NumPy array}`` on the CPU and on ``cuda:0``."""
    return [run(device) for device in DEVICES]


#: Gradients of one parameter that every pixel adds to: tens of thousands of float32 atomic adds
#: into one number, in an order that changes from run to run on CUDA. On an H100 the biplanar
#: tiling gradient (-8.55, from 37k terms of either sign) came out 1.2e-4 relative off the CPU's in
#: one run of two.
SCALARS, SCALAR_RTOL = {"tiling", "transition", "sharpness", "tiling.grad"}, 1e-3


def _compare(cpu: dict, cuda: dict, *, rtol=1e-4, atol=1e-5):
    assert cpu.keys() == cuda.keys()
    for name in cpu:
        a, b = np.asarray(cpu[name], np.float64), np.asarray(cuda[name], np.float64)
        scale = max(float(np.nanmax(np.abs(a))) if a.size else 0.0, 1.0)
        np.testing.assert_allclose(b, a, rtol=max(rtol, SCALAR_RTOL if name in SCALARS else 0.0), atol=atol * scale, err_msg=name)


def _backward(out: wp.array, weights: np.ndarray):
    out.grad.assign(weights[..., : out.shape[-1]].reshape(out.shape))


def test_gbuffer_to_copies_every_array(scene):
    g = scene["gbuffer"]
    there = g.to(OTHER)
    assert str(there.device) == OTHER and there.to(OTHER) is there
    for name, a in g.numpy().items():
        np.testing.assert_array_equal(there.numpy()[name], a, err_msg=name)


def test_rasterize_matches_the_cpu(scene):
    arrays = _on_both(lambda d: wt.rasterize(scene["mesh"], scene["camera"], device=d).numpy())
    cpu, cuda = arrays
    covered = (cpu["mask"] > 0) & (cuda["mask"] > 0)
    assert (cpu["mask"] != cuda["mask"]).mean() < 1e-3  # a silhouette pixel may hit on one device only
    for name in ("position", "normal", "position_dx", "position_dy", "uv0.uv", "uv0.uv_dx", "uv0.uv_dy", "depth"):
        np.testing.assert_allclose(cuda[name][covered], cpu[name][covered], rtol=1e-4, atol=1e-4, err_msg=name)


SAMPLE_CASES = {  # (stochastic method or None, its options, sampler fields, LOD: "array" or a number)
    "bilinear": (None, {}, {"filter": "bilinear"}, None),
    "trilinear lods": (None, {}, {}, "array"),
    "nearest border": (None, {}, {"filter": "nearest", "address": "border", "border": (0.2, 0.4, 0.6, 1.0)}, 1.3),
    "hash4": ("hash4", {"mirror": True}, {}, "array"),
    "cheap2": ("cheap2", {}, {}, "array"),
    "hex": ("hex", {"rotation": 0.5}, {}, "array"),
    "hex histogram": ("hex", {"histogram": True}, {}, 0.8),
}


@pytest.mark.parametrize("case", SAMPLE_CASES)
def test_sample_and_stochastic_match_the_cpu(scene, case):
    """Output and the gradients to the texels and the UVs (the generated adjoint runs then)."""
    method, options, fields, lod = SAMPLE_CASES[case]

    def run(device, uvs=scene["uv"], weights=scene["weights"].reshape(-1, 4)[: len(scene["uv"])]):
        tex = wt.Texture(scene["image"], requires_grad=True, device=device)
        uv = wp.array(uvs, dtype=wp.vec2, device=device, requires_grad=True)
        kw = {"sampler": wt.Sampler(**fields), "lod": wp.array(scene["lod"], dtype=float, device=device) if lod == "array" else lod}
        read = tex
        tape = wp.Tape()
        with tape:
            if method is None:
                out = wt.sample(tex, uv, **kw)
            else:
                if options.get("histogram"):
                    hist = wt.prepare_histogram(tex, requires_grad=True)
                    options_here, read = {**options, "histogram": hist}, hist.texture
                else:
                    options_here = options
                out = wt.stochastic(tex, uv, wt.Stochastic(method, **options_here), **kw)
        out.grad.assign(weights[:, : out.shape[1]])
        tape.backward()
        return {"out": out.numpy(), "uv": uv.grad.numpy(), **{f"texels {k}": read.grad(k) for k in range(read.num_levels)}}

    # A UV within float rounding of a kink (a texel edge, a hex cell's edge, a knot of the
    # histogram's lookup table) may take either side's gradient, to its UV and to its texels: on an
    # H100, one of 5000 hex-histogram samples did. Such a UV's gradient jumps when it moves 4 ulps
    # on the CPU (a second difference past the tolerance); those samples get no output gradient.
    uvs, here = scene["uv"], run("cpu")["uv"]
    stable, atol = np.ones(len(uvs), bool), 1e-5 * max(float(np.abs(here).max()), 1.0)
    for axis in (0, 1):
        step = np.zeros_like(uvs)
        step[:, axis] = 4 * np.spacing(np.abs(uvs[:, axis]))
        both_sides = run("cpu", uvs + step)["uv"] + run("cpu", uvs - step)["uv"]
        stable &= np.isclose(both_sides, 2 * here, rtol=1e-4, atol=atol).all(1)
    assert stable.mean() > 0.95, f"{(~stable).sum()} of {stable.size} UV gradients jump within 4 ulps"
    weights = scene["weights"].reshape(-1, 4)[: len(uvs)] * stable[:, None]
    _compare(*_on_both(lambda device: run(device, weights=weights)))


PLANAR_CASES = {
    "triplanar": (wt.triplanar, {}),
    "triplanar hash4": (wt.triplanar, {"stochastic": "hash4"}),
    "biplanar": (wt.biplanar, {}),
    "triplanar normal": (wt.triplanar_normal, {"blend": "rnm", "strength": 0.7}),
}


@pytest.mark.parametrize("grads", ["texels", "texels and tiling"])
@pytest.mark.parametrize("case", PLANAR_CASES)
def test_planar_techniques_match_the_cpu(scene, case, grads):
    """Output and texel gradients (the hand-written path), then texel and tiling gradients together
    (the generated adjoint)."""
    technique, opts = PLANAR_CASES[case]

    def run(device):
        g = scene["gbuffer"].to(device)
        tex = wt.Texture(scene["image"][..., :3], requires_grad=True, device=device)
        tiling = wp.array([0.4], dtype=float, device=device, requires_grad=grads != "texels")
        tape = wp.Tape()
        with tape:
            out = technique(g, tex, tiling=tiling, **opts)
        _backward(out, scene["weights"])
        tape.backward()
        result = {"out": out.numpy(), **{f"texels {k}": tex.grad(k) for k in range(tex.num_levels)}}
        if tiling.requires_grad:
            result["tiling"] = tiling.grad.numpy()
        return result

    cpu, cuda = _on_both(run)
    precision = 1e-5
    if technique is wt.triplanar_normal:
        # Mips of a random normal map average towards (0.5, 0.5, 0.5), which decodes to a short
        # vector, and normalising that magnifies rounding: the CPU's own float32 error here is
        # 7e-5 (against the float64 reference). Allow each device that error, and as much relative
        # to each gradient's scale.
        exact = rt.triplanar_normal(scene["gbuffer"].numpy(), [scene["image"][..., :3]] * 3, tiling=0.4, blend_kind="rnm", strength=0.7)
        precision = max(precision, float(np.abs(cpu["out"] - exact).max()))
    _compare(cpu, cuda, atol=2 * precision)


@pytest.mark.parametrize("projection", ["uv", "world_xz", "triplanar"])
@pytest.mark.parametrize("grads", ["texels", "with sharpness"])
def test_splat_matches_the_cpu(scene, projection, grads):
    """Output and the gradients to the layers, the splat maps, the tiling and the transition: by
    hand, then (a sharpness needing gradients) through the generated adjoint."""

    def run(device):
        g = scene["gbuffer"].to(device)
        layers = wt.TextureArray(scene["layers"], requires_grad=True, device=device)
        maps = wt.TextureArray(scene["maps"], mipmaps=False, requires_grad=True, device=device)
        tiling = wp.array([8.0, 6.0, 4.0, 5.0] if projection == "uv" else [0.3, 0.25, 0.2, 0.35], dtype=float, device=device, requires_grad=True)
        transition = wp.array([0.2], dtype=float, device=device, requires_grad=True)
        sharpness = wp.array([4.0], dtype=float, device=device, requires_grad=grads != "texels")
        tape = wp.Tape()
        with tape:
            out = wt.splat(g, layers, maps, tiling=tiling, projection=projection, height_blend=transition, sharpness=sharpness)
        _backward(out, scene["weights"])
        tape.backward()
        result = {"out": out.numpy(), "maps": maps.grad(0), "tiling": tiling.grad.numpy(), "transition": transition.grad.numpy()}
        result.update({f"layers {k}": layers.grad(k) for k in range(layers.num_levels)})
        if sharpness.requires_grad:
            result["sharpness"] = sharpness.grad.numpy()
        return result

    _compare(*_on_both(run), rtol=1e-3)


def test_splat_atlas_matches_the_cpu(scene):
    def run(device):
        g = scene["gbuffer"].to(device)
        atlas = wt.pack_atlas(wt.TextureArray(scene["layers"], device=device), gutter=4, requires_grad=True)
        idx, w = wt.export_index_maps(scene["maps"][0], k=2)
        tape = wp.Tape()
        with tape:
            out = wt.splat_atlas(g, atlas, idx, w, tiling=4.0)
        _backward(out, scene["weights"])
        tape.backward()
        return {"out": out.numpy(), **{f"atlas {k}": atlas.texture.grad(k) for k in range(atlas.texture.num_levels)}}

    _compare(*_on_both(run))


def _histogram(tex, uv):
    hist = wt.prepare_histogram(tex, requires_grad=True)
    return wt.stochastic(tex, uv, wt.Stochastic("hex", histogram=hist), lod=1.3), hist.texture


def _atlas(g, layers, maps):
    with paused_tape():  # packed off the tape, so that the atlas keeps its texel gradients
        atlas = wt.pack_atlas(layers, gutter=4, requires_grad=True)
    idx, w = wt.export_index_maps(maps.numpy(0), k=2)
    return wt.splat_atlas(g, atlas, idx, w, tiling=4.0), atlas.texture


# Each case: (output, the texture whose gradient is checked). The last four run Warp's generated
# adjoint (another gradient than texels, a blend not linear in them, no hand-written gradient),
# whose texel reads add in fixed point too (``warptex._accumulate.exact_views``).
DETERMINISM_CASES = {
    "sample trilinear": lambda g, tex, layers, maps, uv: (wt.sample(tex, uv, lod=1.3, sampler=wt.Sampler(filter="trilinear")), tex),
    "triplanar": lambda g, tex, layers, maps, uv: (wt.triplanar(g, tex, tiling=0.4), tex),
    "biplanar hash4": lambda g, tex, layers, maps, uv: (wt.biplanar(g, tex, tiling=0.4, stochastic="hash4"), tex),
    "splat": lambda g, tex, layers, maps, uv: (wt.splat(g, layers, maps, projection="world_xz", tiling=0.3, height_blend=0.2), layers),
    "sample anisotropic": lambda g, tex, layers, maps, uv: (
        wt.sample(tex, uv, uv_dx=uv.numpy() * 0.01, uv_dy=uv.numpy()[:, ::-1] * 0.003, sampler=wt.Sampler(filter="anisotropic")), tex
    ),
    "stochastic hash4": lambda g, tex, layers, maps, uv: (wt.stochastic(tex, uv, "hash4", lod=1.3), tex),
    "stochastic cheap2": lambda g, tex, layers, maps, uv: (wt.stochastic(tex, uv, "cheap2", lod=1.3), tex),
    "stochastic hex": lambda g, tex, layers, maps, uv: (wt.stochastic(tex, uv, "hex", lod=1.3), tex),
    "triplanar_normal": lambda g, tex, layers, maps, uv: (wt.triplanar_normal(g, tex, tiling=0.4), tex),
    "biplanar_normal hash4": lambda g, tex, layers, maps, uv: (wt.biplanar_normal(g, tex, tiling=0.4, stochastic="hash4"), tex),
    "splat triplanar hash4": lambda g, tex, layers, maps, uv: (wt.splat(g, layers, maps, projection="triplanar", tiling=0.3, stochastic="hash4"), layers),
    "sample trilinear, UV gradients": lambda g, tex, layers, maps, uv: (
        wt.sample(tex, wp.array(uv.numpy(), dtype=wp.vec2, requires_grad=True, device=uv.device), lod=1.3, sampler=wt.Sampler(filter="trilinear")), tex
    ),
    "triplanar, tiling gradient": lambda g, tex, layers, maps, uv: (wt.triplanar(g, tex, tiling=wp.array([0.4], dtype=float, requires_grad=True, device=uv.device)), tex),
    "six-planar (one texture on every face)": lambda g, tex, layers, maps, uv: (wt.triplanar(g, None, textures_per_face=[tex] * 6, tiling=0.4), tex),
    "hex, histogram-preserving": lambda g, tex, layers, maps, uv: _histogram(tex, uv),
    "splat_atlas": lambda g, tex, layers, maps, uv: _atlas(g, layers, maps),
}


@pytest.mark.parametrize("case", DETERMINISM_CASES)
def test_texel_gradients_are_the_same_bits_every_run(scene, case):
    """Five backward passes of one call give the texels the same gradients, bit for bit (issue 51).
    The CPU adds in a fixed order (fixed chunks, private copies added in chunk order); CUDA sums
    texel gradients in fixed point, an integer sum that the order the threads add in cannot change
    (``warptex._accumulate.exact_sums``; tests/test_exact_sums.py runs it on the CPU)."""

    def run(device):
        g = scene["gbuffer"].to(device)
        tex = wt.Texture(scene["image"], requires_grad=True, device=device)
        layers = wt.TextureArray(scene["layers"], requires_grad=True, device=device)
        maps = wt.TextureArray(scene["maps"], mipmaps=False, device=device)
        uv = wp.array(scene["uv"], dtype=wp.vec2, device=device)
        tape = wp.Tape()
        with tape:
            out, read = DETERMINISM_CASES[case](g, tex, layers, maps, uv)
        out.grad.assign(scene["weights"].reshape(-1, 4)[: out.shape[0], : out.shape[-1]] if out.ndim == 2 else scene["weights"][..., : out.shape[-1]])
        tape.backward()
        return np.concatenate([read.grad(k).ravel() for k in range(read.num_levels)])

    first = run(OTHER)
    assert np.abs(first).sum() > 0
    for _ in range(4):
        np.testing.assert_array_equal(run(OTHER), first)


def test_a_small_call_is_captured_in_a_cuda_graph(scene):
    """Issue 51: a call into out= is capturable (``wp.ScopedCapture``): the graph's replay fills
    out= as the call does."""
    if not OTHER.startswith("cuda"):
        pytest.skip("CUDA graphs need a CUDA device")
    tex = wt.Texture(scene["image"], device=OTHER)
    uv = wp.array(scene["uv"], dtype=wp.vec2, device=OTHER)
    out = wp.empty((uv.shape[0], 4), dtype=wp.float32, device=OTHER)
    g = scene["gbuffer"].to(OTHER)
    colour = wp.empty((*g.resolution, 4), dtype=wp.float32, device=OTHER)
    for _ in range(2):  # modules loaded and arguments packed outside the capture
        wt.sample(tex, uv, out=out)
        wt.triplanar(g, tex, tiling=0.4, out=colour)
    with wp.ScopedCapture(device=OTHER) as capture:
        wt.sample(tex, uv, out=out)
        wt.triplanar(g, tex, tiling=0.4, out=colour)
    out.zero_()
    colour.zero_()
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(out.numpy(), wt.sample(tex, uv).numpy())
    np.testing.assert_array_equal(colour.numpy(), wt.triplanar(g, tex, tiling=0.4).numpy())


def test_new_arrays_each_call_run_a_kept_plan_on_the_device(scene):
    """Issue 51: on the device too, a loop that makes new UVs and a new ``out=`` each call, or gives
    no ``out=``, runs one kept plan pointed at its arrays (on an H200, a 1-UV call with new UVs
    took 153 us and one into a new output 72 us, against 30 us into a kept ``out=``, while CUDA
    plans served only the arrays they were made with and kept no spare outputs): each call's
    bits, and the dropped outputs written again, on the stream that wrote them only."""
    from warptex import _plan

    tex = wt.Texture(scene["image"], device=OTHER)
    rng = np.random.default_rng(3)
    outputs = []
    for _ in range(8):
        uv = wp.array(rng.uniform(-2, 2, (300, 2)).astype(np.float32), dtype=wp.vec2, device=OTHER)
        out = wp.full((300, 4), np.nan, dtype=wp.float32, device=OTHER)
        with wp.Tape():  # no plan runs under a tape: the call's own path
            want = wt.sample(tex, uv).numpy()
        assert wt.sample(tex, uv, out=out) is out
        new = wt.sample(tex, uv)
        np.testing.assert_array_equal(out.numpy(), want)
        np.testing.assert_array_equal(new.numpy(), want)
        outputs.append(weakref.ref(new))
        del new
    plans = [p for (key, *_), p in _plan._local.plans.items() if key[0] == "sample" and p.cmd is not None]
    assert len(plans) == 2  # one into out=, one making new outputs
    spares = {id(o()) for o in outputs if o() is not None}
    assert len(spares) == 1 and sum(o() is not None for o in outputs) == 6  # from the plan's first run, each output dropped is written again
    if OTHER.startswith("cuda"):
        with wp.ScopedStream(wp.Stream(OTHER)):  # another stream: its write could overtake one still pending
            elsewhere = wt.sample(tex, uv)
            np.testing.assert_array_equal(elsewhere.numpy(), want)
        assert id(elsewhere) not in spares


def test_the_torch_bridge_in_a_torch_cuda_graph(scene):
    """Issue 51: warptex.torch inside ``torch.cuda.graph``: replaying the graph recomputes the
    output from the static input tensors' current contents. (Its first run on a GPU found the bridge
    making torch's stream wait on Warp's, which invalidates a capture.)"""
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    import warptex.torch as wtt

    if not OTHER.startswith("cuda") or not torch.cuda.is_available():
        pytest.skip("torch CUDA graphs need a CUDA device and a CUDA build of PyTorch")
    tdev = wp.device_to_torch(OTHER)
    texture = torch.tensor(scene["image"], device=tdev)
    uv = torch.tensor(scene["uv"], device=tdev)
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):  # warm-up on a side stream, as torch's CUDA graph docs ask
        for _ in range(3):
            wtt.sample(texture, uv)
    torch.cuda.current_stream().wait_stream(side)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph):
        static_out = wtt.sample(texture, uv)
    uv.copy_(torch.tensor(scene["uv"][::-1].copy(), device=tdev))
    graph.replay()
    torch.cuda.synchronize()
    native = wt.sample(wt.Texture(scene["image"], device=OTHER), wp.array(scene["uv"][::-1].copy(), dtype=wp.vec2, device=OTHER))
    np.testing.assert_array_equal(static_out.cpu().numpy(), native.numpy())


def _cli(*args, cwd):
    result = subprocess.run([sys.executable, "-m", "warptex", *args, "--device", OTHER], capture_output=True, text=True, cwd=cwd, timeout=1800)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-4000:]
    return result


def test_render_runs_on_cuda(tmp_path):
    _cli("render", "--out", str(tmp_path / "out"), "--resolution", "128x160", cwd=tmp_path)
    for name in ("render.png", "albedo.png", "normals.png", "render.exr", "gbuffer.exr"):
        assert (tmp_path / "out" / name).stat().st_size > 0


def test_fit_runs_on_cuda(tmp_path):
    _cli("fit", "--out", str(tmp_path / "fit"), "--iters", "20", "--resolution", "96x128", cwd=tmp_path)
    summary = json.loads((tmp_path / "fit" / "summary.json").read_text())
    assert np.isfinite(summary["final_psnr_db"]) and summary["final_psnr_db"] > summary["initial_psnr_db"] + 3


def test_torch_bridge_on_cuda(scene):
    """warptex.torch on a CUDA tensor (torch's current stream): the CPU's outputs and gradients,
    batched views included."""
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch)")
    import warptex.torch as wtt

    if OTHER.startswith("cuda") and not torch.cuda.is_available():
        pytest.skip("this PyTorch build has no CUDA")
    cameras = [scene["camera"], wt.look_at((30.0, 34.0, -40.0), (-2.0, 2.0, 4.0), resolution=(96, 128))]  # a batch of two views
    views = wt.rasterize(scene["mesh"], cameras, device="cpu")

    def run(device):
        tdev = wp.device_to_torch(device)
        g = views.to(device)
        texture = torch.tensor(scene["image"], device=tdev, requires_grad=True)
        layers = torch.tensor(scene["layers"], device=tdev, requires_grad=True)
        maps = torch.tensor(scene["maps"][0], device=tdev, requires_grad=True)
        tiling = torch.tensor(0.3, device=tdev, requires_grad=True)
        uv = torch.tensor(scene["uv"], device=tdev, requires_grad=True)
        colour = wtt.triplanar(g, texture, tiling=tiling, sampler=wt.Sampler(filter="anisotropic"))
        terrain_colour = wtt.splat(g, layers, maps, projection="triplanar", height_blend=0.2, tiling=tiling)
        sampled = wtt.sample(texture, uv, lod=torch.tensor(scene["lod"], device=tdev))
        r = torch.tensor(scene["weights"], device=tdev)
        loss = (colour * r[..., :4]).sum() + (terrain_colour * r[..., :4]).sum() + sampled.sum()
        loss.backward()
        out = {"colour": colour, "splat": terrain_colour, "sampled": sampled, "texture.grad": texture.grad, "layers.grad": layers.grad, "maps.grad": maps.grad, "tiling.grad": tiling.grad, "uv.grad": uv.grad}
        return {k: v.detach().cpu().numpy() for k, v in out.items()}

    _compare(*_on_both(run), rtol=1e-3, atol=1e-4)
