"""Fitting: parameterisations, blur, loss, entropy and Adam against NumPy references;
gradients of the whole pipeline (rasterised G-buffer → softmax/exp/softplus → splat → loss)
against finite differences; the loop and the tiling scan on small views; bad input; the example."""

import json

import numpy as np
import pytest
import warp as wp
import warp.optim

import warptex as wt
from warptex.scenes.terrain import terrain
from warptex import io
from warptex.apps.cli import main as cli_main
from warptex.apps.fit_report import splat_coverage
from warptex.fit import FitView, Objective, SplatParameters, Stage, blur, fit_splat, gaussian_taps, image_loss, prepare_views, psnr, render_views, weight_entropy
from warptex.kernels import fit as kf
from warptex.scenes import terrain_camera

TRANSITION = 0.2
OPTIONS = {"projection": "triplanar", "height_blend": TRANSITION}


def smooth_layers(count: int, size: int = 32, seed: int = 0) -> np.ndarray:
    """``[count, size, size, 4]`` smooth periodic layers: distinct RGB, height in alpha (low
    frequencies only, so finite differences see few bilinear kinks)."""
    rng = np.random.default_rng(seed)
    y, x = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size, indexing="ij")
    out = []
    for k in range(count):
        img = np.full((size, size, 4), 0.5)  # alpha: height around 0.5
        img[..., :3] = rng.uniform(0.2, 0.8, 3)
        for _ in range(3):
            fx, fy = rng.integers(-2, 3, size=2)
            img += 0.08 * np.sin(2 * np.pi * (fx * x + fy * y)[..., None] + rng.uniform(0, 2 * np.pi, 4))
        out.append(np.clip(img, 0.0, 1.0))
    return np.stack(out).astype(np.float32)


@pytest.fixture(scope="module")
def scene():
    """A coarse terrain seen by the default camera at 24 × 32, smooth layers, a target rendered
    with random true weights at tiling 0.2 (maps 9 × 9)."""
    mesh = terrain(resolution=(33, 33))
    g = wt.rasterize(mesh, terrain_camera((24, 32)))
    layers = wt.TextureArray(smooth_layers(4))
    rng = np.random.default_rng(5)
    true = rng.dirichlet(np.full(4, 0.7), size=(9, 9)).astype(np.float32)
    target = wt.splat(g, layers, wt.TextureArray(true[None], mipmaps=False), tiling=0.2, **OPTIONS).numpy()[..., :3]
    return {"g": g, "layers": layers, "true": true, "target": target, "mesh": mesh}


# -- parameterisations against NumPy ---------------------------------------------------------------------


def _softmax(z: np.ndarray) -> np.ndarray:
    e = np.exp(z - z.max(axis=0))
    return e / e.sum(axis=0)


@pytest.mark.parametrize("num_layers, channels, num_maps", [(4, 4, 1), (5, 3, 2), (2, 4, 1)])
def test_softmax_writes_the_splat_maps_and_its_gradient_matches_numpy(rng, num_layers, channels, num_maps):
    size = (5, 6)
    params = SplatParameters(num_layers, size, channels=channels, num_maps=num_maps)
    z = rng.normal(scale=3.0, size=(num_layers, *size)).astype(np.float32)
    params.logits.assign(z.reshape(-1))
    upstream = rng.normal(size=(num_maps, *size, 4)).astype(np.float32)
    tape = wp.Tape()
    with tape:
        params.apply()
    params.maps.texels.grad.assign(upstream)
    tape.backward()

    w = _softmax(z.astype(np.float64))  # [L, H, W]
    expected = np.zeros((num_maps, *size, 4))
    for layer in range(num_layers):
        expected[layer // channels, ..., layer % channels] = w[layer]
    np.testing.assert_allclose(params.maps.texels.numpy(), expected, atol=1e-6)  # spare channels are 0
    np.testing.assert_allclose(params.weights().transpose(2, 0, 1), w, atol=1e-6)

    g = np.stack([upstream[layer // channels, ..., layer % channels] for layer in range(num_layers)])  # dL/dw
    expected_grad = w * (g - (w * g).sum(axis=0))  # softmax Jacobian-vector product
    np.testing.assert_allclose(params.logits.grad.numpy().reshape(num_layers, *size), expected_grad, atol=1e-5)


def test_softmax_is_stable_for_large_logits():
    params = SplatParameters(3, (1, 2))
    params.logits.assign(np.array([200.0, -50.0, 0.0, 0.0, 150.0, 0.0], np.float32))
    params.apply()
    w = params.maps.numpy()[0]
    assert np.isfinite(w).all()
    np.testing.assert_allclose(w.sum(axis=-1), 1.0, atol=1e-6)
    np.testing.assert_allclose(w[0, :, 0], [1.0, 0.0], atol=1e-6)


def test_exp_and_softplus_values_and_gradients_match_numpy():
    x = np.array([-30.0, -2.0, -0.1, 0.0, 0.7, 3.0, 40.0], np.float32)
    for kernel, f, df in (
        (kf.exp_kernel, np.exp, np.exp),
        (kf.softplus_kernel, lambda v: np.logaddexp(0.0, v), lambda v: 1.0 / (1.0 + np.exp(-v))),
    ):
        xs = wp.array(x, dtype=float, requires_grad=True)
        out = wp.zeros(len(x), dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            wp.launch(kernel, dim=len(x), inputs=[xs], outputs=[out])
        out.grad.fill_(1.0)
        tape.backward()
        x64 = x.astype(np.float64)
        np.testing.assert_allclose(out.numpy(), f(x64), rtol=1e-6, atol=1e-30)
        np.testing.assert_allclose(xs.grad.numpy(), df(x64), rtol=1e-5, atol=1e-30)


def test_parameters_start_where_asked():
    weights = np.random.default_rng(0).dirichlet(np.ones(4), size=(3, 5))
    params = SplatParameters(4, (3, 5), weights=weights, tiling=[0.1, 0.2, 0.3, 0.4], sharpness=6.0)
    np.testing.assert_allclose(params.weights(), weights, atol=2e-4)  # logits = log(max(w, 1e-4))
    np.testing.assert_allclose(params.tiling.numpy(), [0.1, 0.2, 0.3, 0.4], rtol=1e-6)
    np.testing.assert_allclose(params.sharpness.numpy(), [6.0], rtol=1e-6)
    uniform = SplatParameters(3, (2, 2))
    np.testing.assert_allclose(uniform.maps.numpy()[0, ..., :3], 1 / 3, rtol=1e-6)


# -- blur, loss, entropy, Adam against NumPy -------------------------------------------------------------


def _blur_reference(img: np.ndarray, sigma: float) -> np.ndarray:
    taps = gaussian_taps(sigma).astype(np.float64)
    r = len(taps) // 2
    pad = np.pad(img.astype(np.float64), ((r, r), (r, r), (0, 0)))
    rows = sum(taps[k] * pad[:, k : k + img.shape[1]] for k in range(len(taps)))
    return sum(taps[k] * rows[k : k + img.shape[0]] for k in range(len(taps)))


def test_gaussian_taps():
    taps = gaussian_taps(1.5)
    assert len(taps) == 2 * 5 + 1 and abs(taps.sum() - 1) < 1e-6
    x = np.arange(-5, 6)
    np.testing.assert_allclose(taps, np.exp(-0.5 * (x / 1.5) ** 2) / np.exp(-0.5 * (x / 1.5) ** 2).sum(), rtol=1e-6)
    np.testing.assert_array_equal(gaussian_taps(0.0), [1.0])
    with pytest.raises(ValueError, match=r"gaussian_taps\(\): sigma must be >= 0"):
        gaussian_taps(-1.0)


def test_blur_and_its_adjoint_match_numpy(rng):
    img = rng.random((13, 17, 4)).astype(np.float32)
    src = wp.array(img, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        out = blur(src, 1.3, channels=3)
    np.testing.assert_allclose(out.numpy(), _blur_reference(img[..., :3], 1.3), atol=1e-6)
    upstream = rng.normal(size=(13, 17, 3)).astype(np.float32)
    out.grad.assign(upstream)
    tape.backward()
    # A symmetric zero-padded filter is its own transpose: the adjoint is the blur of the upstream gradient.
    np.testing.assert_allclose(src.grad.numpy()[..., :3], _blur_reference(upstream, 1.3), atol=1e-5)
    np.testing.assert_array_equal(src.grad.numpy()[..., 3], 0.0)
    assert blur(src, 0.0) is src


@pytest.mark.parametrize("kind", ["l2", "l1"])
def test_image_loss_and_its_gradient_match_numpy(rng, kind):
    render = rng.random((6, 7, 4)).astype(np.float32)
    target = rng.random((6, 7, 3)).astype(np.float32)
    weight = (rng.random((6, 7)) * (rng.random((6, 7)) > 0.3)).astype(np.float32)
    r = wp.array(render, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        loss = image_loss(r, target, weight=weight, loss=kind)
    tape.backward(loss=loss)
    d = render[..., :3].astype(np.float64) - target
    scale = 1.0 / (3 * weight.astype(np.float64).sum())
    rho, drho = (d**2, 2 * d) if kind == "l2" else (np.sqrt(d**2 + 1e-12), d / np.sqrt(d**2 + 1e-12))
    assert loss.dtype == wp.float64
    np.testing.assert_allclose(loss.numpy()[0], (weight[..., None] * rho).sum() * scale, rtol=1e-6)
    grad = r.grad.numpy()
    np.testing.assert_allclose(grad[..., :3], weight[..., None] * drho * scale, rtol=1e-5, atol=1e-9)
    np.testing.assert_array_equal(grad[..., 3], 0.0)  # the render's extra (height) channel is not compared
    if kind == "l2":
        mse = float(((render[..., :3] - target) ** 2).mean())
        assert psnr(float(image_loss(render, target).numpy()[0])) == pytest.approx(-10 * np.log10(mse), rel=1e-5)


def test_weight_entropy_and_its_gradient_match_numpy(rng):
    params = SplatParameters(3, (4, 5))
    z = rng.normal(size=(3, 4, 5)).astype(np.float32)
    params.logits.assign(z.reshape(-1))
    tape = wp.Tape()
    with tape:
        params.apply()
        value = weight_entropy(params, 0.5)
    tape.backward(loss=value)
    w = _softmax(z.astype(np.float64))
    entropy = -(w * np.log(w)).sum(axis=0)
    np.testing.assert_allclose(value.numpy()[0], 0.5 * entropy.mean(), rtol=1e-5)
    expected = -w * (np.log(w) + entropy) * 0.5 / 20  # dH/dz_k = -w_k (log w_k + H)
    np.testing.assert_allclose(params.logits.grad.numpy().reshape(3, 4, 5), expected, atol=1e-6)


def test_adam_matches_numpy():
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=7)
    grads = rng.normal(size=(4, 7))
    x = wp.array(x0.astype(np.float32), dtype=float)
    opt = warp.optim.Adam([x], lr=0.1, betas=(0.9, 0.999), eps=1e-8)
    m, v, ref = np.zeros(7), np.zeros(7), x0.copy()
    for t, (g, lr) in enumerate(zip(grads, (0.1, 0.1, 0.05, 0.02)), start=1):
        opt.lr = lr  # fit_splat's cosine schedule changes lr between steps
        opt.step([wp.array(g.astype(np.float32), dtype=float)])
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        ref -= lr * (m / (1 - 0.9**t)) / (np.sqrt(v / (1 - 0.999**t)) + 1e-8)
    np.testing.assert_allclose(x.numpy(), ref, rtol=1e-5, atol=1e-6)


def test_coverage_counts_bilinear_weight_per_texel():
    # A texel centre gives its texel weight 1; a point between four centres gives each 1/4.
    uv_centre = np.array([[(2 + 0.5) / 4, 1 - (1 + 0.5) / 3]])
    uv_corner = np.array([[2 / 4, 1 - 2 / 3]])
    cover = splat_coverage([uv_centre, uv_corner], (3, 4))
    expected = np.zeros((3, 4))
    expected[1, 2] = 1.0
    expected[1:3, 1:3] += 0.25
    np.testing.assert_allclose(cover, expected, atol=1e-12)
    assert splat_coverage([np.random.default_rng(0).random((50, 2))], (5, 5)).sum() == pytest.approx(50.0)


# -- gradients of the whole pipeline against finite differences ---------------------------------------------


def _pipeline(scene, params, weight):
    """``softmax/exp/softplus → splat → loss`` on the scene's rasterised G-buffer, float64 loss."""
    opts = dict(OPTIONS)
    if params.sharpness is not None:
        opts["sharpness"] = params.sharpness
    params.apply()
    out = wt.splat(scene["g"], scene["layers"], params.maps, tiling=params.tiling, **opts)
    return out, image_loss(out, scene["target"], weight=weight, scale=1.0)


def _loss_and_render(scene, params, weight):
    out, loss = _pipeline(scene, params, weight)
    return float(loss.numpy()[0]), out.numpy()[..., :3].astype(np.float64)


def _analytic(scene, params, weight):
    tape = wp.Tape()
    with tape:
        _, loss = _pipeline(scene, params, weight)
    tape.backward(loss=loss)
    grads = {"logits": params.logits.grad.numpy().copy(), "log_tiling": params.log_tiling.grad.numpy().copy()}
    if params.sharpness_raw is not None:
        grads["sharpness_raw"] = params.sharpness_raw.grad.numpy().copy()
    tape.zero()
    return grads


def _check_fd(scene, params, array, index, step, *, min_kept=0.9):
    """Central difference of the loss in ``array[index]`` against the backward pass. Pixels whose
    render has one-sided differences that disagree (a bilinear line, a mip level or a height-blend
    switch inside the step: the criterion of ``fd.check_parameter_gradient``) get loss weight 0 in
    both, and at least ``min_kept`` of the covered pixels must remain."""
    base = array.numpy().copy()
    mask = scene["g"].mask.numpy()

    def at(delta, weight):
        v = base.copy()
        v[index] += delta
        array.assign(v)
        return _loss_and_render(scene, params, weight)

    (_, minus), (_, centre), (_, plus) = (at(d, mask) for d in (-step, 0.0, step))
    forward, backward, central = (plus - centre) / step, (centre - minus) / step, (plus - minus) / (2 * step)
    smooth = (np.abs(forward - backward) <= 1e-2 * (1 + np.abs(central))).all(axis=-1)
    covered = mask > 0
    assert smooth[covered].mean() >= min_kept, f"too few smooth pixels ({smooth[covered].mean():.2f})"
    weight = (mask * smooth).astype(np.float32)
    fd = (at(step, weight)[0] - at(-step, weight)[0]) / (2 * step)
    array.assign(base)
    grad = _analytic(scene, params, weight)
    name = next(k for k, a in (("logits", params.logits), ("log_tiling", params.log_tiling), ("sharpness_raw", params.sharpness_raw)) if a is array)
    return grad[name][index], fd


def test_logit_and_tiling_gradients_match_finite_differences_of_the_whole_pipeline(scene, rng):
    true = scene["true"]
    start = np.clip(true + rng.normal(scale=0.15, size=true.shape), 0.02, None)
    params = SplatParameters(4, (9, 9), weights=start, tiling=0.2 * 1.04, sharpness=4.0)
    # A handful of logits on the texels the view sees most, every layer once.
    uv = scene["g"].uv_sets["uv0"]["uv"].numpy()[scene["g"].mask.numpy() > 0]
    seen = np.argsort(splat_coverage([uv], (9, 9)).reshape(-1))[::-1][:6]
    checked = 0
    for k, texel in enumerate(seen):
        analytic, fd = _check_fd(scene, params, params.logits, ((k % 4) * 81 + texel,), 1e-2)
        assert abs(fd) > 1e-6, "the chosen logit moves the loss"
        np.testing.assert_allclose(analytic, fd, rtol=2e-2, atol=1e-7, err_msg=f"logit of layer {k % 4}, texel {texel}")
        checked += 1
    analytic, fd = _check_fd(scene, params, params.log_tiling, (0,), 2e-4)  # the textures curve fast in tiling
    assert abs(fd) > 1e-5
    np.testing.assert_allclose(analytic, fd, rtol=2e-2, err_msg="log tiling")
    analytic, fd = _check_fd(scene, params, params.sharpness_raw, (0,), 1e-2)
    np.testing.assert_allclose(analytic, fd, rtol=2e-2, atol=1e-7, err_msg="softplus sharpness")
    assert checked == 6


def test_objective_gradient_through_blur_views_and_prior_matches_finite_differences(scene, rng):
    # fit_splat's objective: two views, mask + blur of the render, the entropy prior; along a
    # random direction in all logits (the loss is smooth in the weights away from height-blend switches).
    g2 = wt.rasterize(scene["mesh"], wt.look_at((20.0, 30.0, 25.0), (0.0, 3.0, 0.0), resolution=(20, 20)))
    views = [FitView(scene["g"], scene["target"]), FitView(g2, wt.splat(g2, scene["layers"], wt.TextureArray(scene["true"][None], mipmaps=False), tiling=0.2, **OPTIONS).numpy()[..., :3])]
    params = SplatParameters(4, (9, 9), tiling=0.2)
    device = wp.get_device()
    objective = Objective(prepare_views("t", views, scene["layers"], params, device), scene["layers"], params, dict(OPTIONS), wt.fit.Loss.L2, 1e-3, device)
    tape = wp.Tape()
    with tape:
        params.apply()
        value, _ = objective(1.5)
    tape.backward(loss=value)
    grad = params.logits.grad.numpy().astype(np.float64)
    tape.zero()
    z0 = params.logits.numpy().copy()
    direction = rng.normal(size=z0.shape)
    step = 2e-3

    def loss_at(t):
        params.logits.assign((z0 + t * direction).astype(np.float32))
        params.apply()
        return float(objective(1.5)[0].numpy()[0])

    fd = (loss_at(step) - loss_at(-step)) / (2 * step)
    np.testing.assert_allclose((grad * direction).sum(), fd, rtol=2e-2)


# -- the loop --------------------------------------------------------------------------------------------


def test_fit_recovers_weights_and_the_scan_recovers_tiling(scene):
    params = SplatParameters(4, (9, 9), tiling=0.2 * 1.2)
    stages = [Stage(30, sigma=1.0, lr_logits=0.2), Stage(0, scan=(0.35, 71)), Stage(40, lr_logits=0.1, lr_tiling=0.005, decay=0.2)]
    result = fit_splat(FitView(scene["g"], scene["target"]), scene["layers"], params, stages=stages, splat_options=OPTIONS, progress=False)
    assert result.iterations == 70 and len(result.history["psnr"]) == 70 and result.history["stage"][-1] == 2
    assert abs(result.scans[0]["chosen"] / 0.2 - 1) < 0.02, result.scans[0]["chosen"]
    assert abs(params.tiling_values()[0] / 0.2 - 1) < 0.01
    assert result.final_psnr > psnr(result.initial_mse) + 15 and result.final_psnr > 35
    covered = scene["g"].mask.numpy() > 0
    render = render_views(FitView(scene["g"], scene["target"]), scene["layers"], params, splat_options=OPTIONS)[0][..., :3]
    assert np.mean((render - scene["target"])[covered] ** 2) == pytest.approx(result.final_mse, rel=1e-4)
    assert result.history["loss"][-1] < 0.05 * result.history["loss"][0]


def test_a_mask_leaves_pixels_out(scene):
    # Pixels with mask 0 may hold anything, NaN included; fractional weights count in sharp and blurred stages.
    g, target = scene["g"], scene["target"]
    mask = g.mask.numpy() * np.linspace(0.2, 1.0, 32, dtype=np.float32)[None, :]
    mask[:, :12] = 0.0
    bad = target.copy()
    bad[:, :12] = np.nan
    params = SplatParameters(4, (9, 9), tiling=0.2)
    result = fit_splat(FitView(g, bad, mask=mask), scene["layers"], params, stages=[Stage(3, sigma=1.5), Stage(3)], splat_options=OPTIONS, progress=False)
    assert np.isfinite(params.logits.numpy()).all() and np.isfinite(result.history["loss"]).all()
    render = render_views(FitView(g, bad), scene["layers"], params, splat_options=OPTIONS)[0][..., :3]
    sq = np.where(mask[..., None] > 0, render - np.nan_to_num(bad), 0.0) ** 2
    np.testing.assert_allclose(result.final_mse, (mask[..., None] * sq).sum() / (3 * mask.sum()), rtol=1e-4)


# -- bad input -------------------------------------------------------------------------------------------


def _untouched(params):
    return np.all(params.logits.numpy() == 0) and params.log_tiling.numpy()[0] == np.float32(np.log(0.2))


def test_a_supersampled_gbuffer_is_refused_with_what_to_do_instead(scene):
    """A fit compares one sample a pixel with its target; a supersampled G-buffer (whose sample
    grid is s times the target's) is named as such, not reported as a size mismatch."""
    g = wt.rasterize(scene["mesh"], terrain_camera((24, 32)).supersampled(4))
    with pytest.raises(ValueError, match=r"view 0's G-buffer is supersampled \(4 samples a pixel\).*not camera.supersampled\(\)"):
        fit_splat(FitView(g, scene["target"]), scene["layers"], SplatParameters(4, (9, 9)), stages=[Stage(1)], splat_options=OPTIONS, progress=False)


def test_bad_input_raises_before_any_iteration(scene):
    g, layers, target = scene["g"], scene["layers"], scene["target"]
    params = SplatParameters(4, (9, 9), tiling=0.2)
    with pytest.raises(ValueError, match=r"fit_splat\(\): view 0: the target is \(24, 31\) \(H, W\) but its G-buffer is \(24, 32\)"):
        fit_splat(FitView(g, target[:, :31]), layers, params, splat_options=OPTIONS, progress=False)
    nan = target.copy()
    covered = np.argwhere(g.mask.numpy() > 0)[3]
    nan[covered[0], covered[1], 1] = np.nan
    with pytest.raises(ValueError, match=r"fit_splat\(\): view 1: the target has 1 non-finite value\(s\) on covered pixels"):
        fit_splat([FitView(g, target), FitView(g, nan)], layers, params, splat_options=OPTIONS, progress=False)
    five = wt.TextureArray(smooth_layers(5, size=8))
    with pytest.raises(ValueError, match=r"fit_splat\(\): 1 splat map\(s\) of 4 channel\(s\) hold weights for 1 to 4 layers, but there are 5 layers"):
        fit_splat(FitView(g, target), five, params, splat_options=OPTIONS, progress=False)
    assert _untouched(params)
    with pytest.raises(ValueError, match=r"SplatParameters\(\): 1 splat map\(s\) of 4 channel\(s\) hold weights for 1 to 4 layers, but there are 6 layers"):
        SplatParameters(6, (9, 9), num_maps=1)
    with pytest.raises(ValueError, match=r"SplatParameters\(\): tiling must be one or 4 positive numbers"):
        SplatParameters(4, (9, 9), tiling=-0.2)
    with pytest.raises(ValueError, match=r"fit_splat\(\): splat_options must not set 'tiling'"):
        fit_splat(FitView(g, target), layers, params, splat_options={"tiling": 0.3}, progress=False)
    with pytest.raises(ValueError, match=r"image_loss\(\): render \(24, 32, 4\) must be \(H, W, C_r\) with the target's H, W = 12, 32"):
        image_loss(wt.splat(g, layers, params.maps, tiling=0.2), target[:12])


def test_cli_reports_bad_input_without_writing_anything(tmp_path, capsys):
    g = wt.rasterize(terrain(resolution=(17, 17)), terrain_camera((16, 20)))
    wt.save_gbuffer(tmp_path / "g.exr", g)
    io.write_png(tmp_path / "small.png", np.full((12, 20, 3), 0.5, np.float32))
    out = tmp_path / "out"
    assert cli_main(["fit", "--out", str(out), "--target", str(tmp_path / "small.png"), "--gbuffer", str(tmp_path / "g.exr"), "--iters", "3"]) == 1
    assert "the target is (12, 20) (H, W) but its G-buffer is (16, 20)" in capsys.readouterr().err
    io.write_exr(tmp_path / "nan.exr", np.where(np.arange(20)[None, :, None] == 7, np.nan, 0.5).repeat(16, 0).repeat(3, 2).astype(np.float32))
    assert cli_main(["fit", "--out", str(out), "--target", str(tmp_path / "nan.exr"), "--gbuffer", str(tmp_path / "g.exr"), "--iters", "3"]) == 1
    assert "non-finite value(s) on covered pixels" in capsys.readouterr().err
    io.write_png(tmp_path / "ok.png", np.full((16, 20, 3), 0.5, np.float32))
    io.write_exr(tmp_path / "map.exr", np.full((9, 9, 4), 0.25, np.float32))
    layers = [str(tmp_path / f"l{k}.png") for k in range(5)]
    for k, path in enumerate(layers):
        io.write_png(path, np.full((8, 8, 4), 0.2 * k, np.float32))
    args = ["fit", "--out", str(out), "--target", str(tmp_path / "ok.png"), "--gbuffer", str(tmp_path / "g.exr"), "--layers", *layers]
    assert cli_main([*args, "--initial-maps", str(tmp_path / "map.exr")]) == 1
    assert "run_fit(): 1 splat map(s) of 4 channel(s) hold weights for 1 to 4 layers, but there are 5 layers" in capsys.readouterr().err
    assert cli_main([*args, "--maps", "1"]) == 1
    assert "hold weights for 1 to 4 layers, but there are 5 layers" in capsys.readouterr().err
    assert not out.exists()


# -- the example and the CLI -------------------------------------------------------------------------------

FILES = ("target.png", "initial.png", "fitted.png", "comparison.png", "splat_true.png", "splat_fitted.png", "splat_maps.png", "splat_fitted.exr", "curve.png", "summary.json")


def test_example_runs_with_few_iterations(tmp_path, capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "fit_splat.py"
    spec = importlib.util.spec_from_file_location("fit_splat_example", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    result = example.fit_example(tmp_path, iters=6, resolution=(24, 32))
    assert set(result) == {"psnr", "tiling", "tiling_error", "weight_mae"}
    assert all(np.isfinite(v) for v in result.values())
    assert result["tiling_error"] < 0.3 and 0.0 < result["weight_mae"] < 1.0
    for name in ("target.png", "fitted.png"):
        image = io.read_image(tmp_path / name)
        assert image.shape == (24, 64, 3), name  # the two views side by side
    assert not list(tmp_path.glob(".*.tmp*")), "no temporary files left behind"


def test_cli_fit_writes_its_report(tmp_path, capsys):
    assert cli_main(["fit", "--out", str(tmp_path), "--iters", "5", "--resolution", "24x32", "--report-every", "1"]) == 0
    printed = capsys.readouterr().out
    assert "iter    5/5" in printed and "psnr" in printed and "splat weights MAE" in printed
    # The column that jumps where a stage starts is named for what it is, and the stages are announced.
    assert not [line for line in printed.splitlines() if line.startswith("iter") and "loss" in line]
    assert "iter    5/5  stage 3  objective " in printed
    assert "'objective' is the stage's loss (blurred, on the stage's pixels, + prior), so it jumps where a stage starts" in printed
    assert "stage 0: 1 iteration, blur 2 px, every 2nd pixel" in printed and "stage 1: tiling scan of 71 tilings" in printed
    assert "stage 3: 3 iterations, sharp" in printed
    for name in FILES:
        assert (tmp_path / name).stat().st_size > 0, name
    assert not list(tmp_path.glob(".*.tmp*")), "no temporary files left behind"
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["iterations"] == 5 and summary["views"] == 2 and summary["mode"] == "synthetic"
    for key in ("final_psnr_db", "splat_mae_covered", "tiling_error_percent", "fit_seconds", "covered_texels"):
        assert np.isfinite(summary[key]), key
    assert summary["final_psnr_db"] > summary["initial_psnr_db"]
    curve = io.read_image(tmp_path / "curve.png")
    assert curve.shape[0] > 200 and curve.shape[1] > 400  # a chart, not a placeholder


@pytest.mark.parametrize(
    "args, message",
    [
        (["--seed", "-1"], "argument --seed: must be at least 0, got -1"),
        (["--target", "x.png"], "--target and --gbuffer go together, one G-buffer per target image; got 1 --target and 0 --gbuffer"),
        (["--gbuffer", "g.exr"], "got 0 --target and 1 --gbuffer"),
        (["--target", "a.png", "--target", "b.png", "--gbuffer", "g.exr"], "got 2 --target and 1 --gbuffer"),
        (["--dist-timeout", "0"], "argument --dist-timeout: must be a finite number > 0"),
    ],
)
def test_bad_fit_options_exit_2_with_the_fit_usage(tmp_path, capsys, args, message):
    with pytest.raises(SystemExit) as info:
        cli_main(["fit", *args, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert info.value.code == 2 and message in err and err.startswith("usage: warptex fit"), err
    assert not (tmp_path / "out").exists()


def test_fit_help_prints_percent_signs_once(capsys):
    with pytest.raises(SystemExit) as info:
        cli_main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert info.value.code == 0 and "weights and a tiling 20% off." in text and "%%" not in text
    assert "torchrun --nproc-per-node N -m warptex fit" in text


def test_layers_without_height_name_the_cli_option(tmp_path, capsys):
    io.write_png(tmp_path / "pat.png", np.full((8, 8, 3), 0.5, np.float32))
    out = tmp_path / "out"
    assert cli_main(["fit", "--out", str(out), "--layers", str(tmp_path / "pat.png"), "--iters", "2", "--resolution", "16x16"]) == 1
    err = capsys.readouterr().err
    assert "height blending reads the height from the layers' alpha, but they have 3 channels" in err
    assert "turn the height blend off (--height-blend none" in err
    assert not out.exists()


def test_cli_fits_a_users_target_and_gbuffer(tmp_path, capsys):
    # warptex render's albedo and G-buffer are a user's target: fit the default layers to them.
    assert cli_main(["render", "--out", str(tmp_path), "--resolution", "20x24"]) == 0
    out = tmp_path / "fit"
    assert cli_main(["fit", "--out", str(out), "--target", str(tmp_path / "albedo.png"), "--gbuffer", str(tmp_path / "gbuffer.exr"), "--iters", "4", "--map-size", "17x17"]) == 0
    assert "fit: 4 iterations" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mode"] == "user" and summary["map_size"] == [17, 17] and "splat_mae_covered" not in summary
    assert io.read_image(out / "splat_fitted.exr").shape == (17, 17, 4)
    assert not (out / "splat_true.png").exists()


def test_a_target_against_the_g_buffer_of_another_view_is_warned_about(tmp_path, capsys):
    """Issue 50 item 14: fitting a target against the wrong, same-size G-buffer ran for minutes
    without a word. A target is far sharper along its own G-buffer's silhouette than elsewhere
    (silhouette_contrast); one of another view is not, and the fit says so before it starts."""
    import warnings

    from warptex.apps.fit_demo import user_problem
    from warptex.fit.objective import LINED_UP_CONTRAST, silhouette_contrast

    views = {"a": "-30,34,40", "b": "-20,30,45", "c": "30,20,-40"}
    for name, eye in views.items():
        assert cli_main(["render", "--out", str(tmp_path / name), "--resolution", "64x80", "--quiet", "--eye", eye]) == 0
    capsys.readouterr()
    image = {k: io.read_image(tmp_path / k / "albedo.png") for k in views}
    mask = {k: io.read_image(tmp_path / k / "gbuffer.exr", channels=["mask"])[..., 0] for k in views}
    for k in views:
        for m in views:
            contrast = silhouette_contrast(image[k], mask[m])
            assert (contrast > 2 * LINED_UP_CONTRAST) if k == m else (contrast < LINED_UP_CONTRAST), (k, m, contrast)
    assert silhouette_contrast(image["a"], np.ones((64, 80))) is None  # no silhouette: nothing to tell
    options = {"layers": None, "tiling": None, "options": {"sampler": wt.Sampler(), "projection": "triplanar", "height_blend": 0.2}, "device": "cpu"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        user_problem("run_fit", [tmp_path / k / "albedo.png" for k in views], [tmp_path / k / "gbuffer.exr" for k in views], **options)
    with pytest.warns(UserWarning, match=r"run_fit\(\): the target '.*b/albedo.png' does not seem to show the view of its G-buffer '.*c/gbuffer.exr'"):
        user_problem("run_fit", [tmp_path / "a" / "albedo.png", tmp_path / "b" / "albedo.png"], [tmp_path / "a" / "gbuffer.exr", tmp_path / "c" / "gbuffer.exr"], **options)


@pytest.mark.parametrize("count", [2, 3, 5])
def test_the_synthetic_fit_takes_any_number_of_layers(tmp_path, count):
    """``warptex fit --layers`` with other than the terrain's four layers fitted, then failed at
    the end (fewer: its score compared L weights with four) or at once with an error about splat
    maps the user never gave (more). The truth gives the terrain's rules to the layers in order:
    the last takes those left out; layers past four weigh nothing."""
    paths = []
    for k, layer in enumerate(smooth_layers(count, seed=3)):
        paths.append(str(tmp_path / f"layer{k}.png"))
        io.write_png(paths[-1], layer)
    out = tmp_path / "fit"
    assert cli_main(["fit", "--layers", *paths, "--iters", "6", "--resolution", "24x32", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["final_psnr_db"] > summary["initial_psnr_db"]
    assert 0.0 <= summary["splat_mae_covered"] < summary["splat_mae_uniform_start"]


def test_the_terrain_rules_become_one_weight_per_layer():
    from warptex.apps.fit_demo import layer_weights, packed_maps

    rules = np.random.default_rng(2).dirichlet(np.ones(4), size=(5, 6)).astype(np.float32)
    three = layer_weights(rules, 3)
    np.testing.assert_array_equal(three[..., :2], rules[..., :2])
    np.testing.assert_allclose(three[..., 2], rules[..., 2] + rules[..., 3])
    six = layer_weights(rules, 6)
    np.testing.assert_array_equal(six[..., :4], rules)
    assert not six[..., 4:].any()
    maps = packed_maps(six)
    assert maps.shape == (2, 5, 6, 4)
    np.testing.assert_array_equal(maps[0], rules)
    np.testing.assert_array_equal(maps[1], 0)
    np.testing.assert_array_equal(packed_maps(three)[0, ..., :3], three)
    assert not packed_maps(three)[0, ..., 3].any()
