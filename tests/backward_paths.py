"""The hand-written texel gradient against Warp's generated adjoint, on the same inputs.

When only texels need gradients, ``sample``, ``stochastic``, ``triplanar``, ``biplanar`` and
``splat`` record a hand-written texel gradient (a ``scatter`` launch; ``splat``'s also gives the
height-blend transition's); when another input needs gradients too, or when the tests force it, the
generated adjoint computes them all. All must give the same gradients.
"""

import numpy as np
import warp as wp

import warptex as wt
from warptex import _op


def texel_gradients_both_ways(monkeypatch, threads: int, forward, weights: np.ndarray):
    """``(hand_written, forced, generated, scatters)``: the gradients of ``Σ weights · out``, one
    ``(is_parameter, flat array)`` per texture (every level) or parameter array that has them: with
    only texels needing gradients (the hand-written path), the same with the generated adjoint
    forced (``warptex._op.force_generated_adjoint``), and with another input needing gradients too
    (the generated adjoint, which then also differentiates that input, not compared); and how many
    hand-written texel-gradient kernels were launched over the three runs (the blends of stored
    samples, which ``splat``'s generated-adjoint path and normal mapping's two-step path launch by
    hand, are not counted).

    ``forward(other_grads) -> (out, textures)`` runs the technique (on a tape) with fresh textures
    (or parameter arrays: their gradients are compared too). Each tape is zeroed afterwards, which
    must reset the gradients.
    """
    scatters = []
    monkeypatch.setattr(_op, "scatter", lambda *a, **k: (scatters.append(a[0].key), wt._launch.scatter(*a, **k)))
    wt.set_num_threads(threads)
    try:
        grads = []
        for other_grads, forced in ((False, False), (False, True), (True, False)):
            tape = wp.Tape()
            with tape, _op.force_generated_adjoint(forced):
                out, textures = forward(other_grads)
            out.grad.assign(weights.reshape(out.shape))
            tape.backward()
            textures = [t for t in textures if t.requires_grad]
            grads.append([(isinstance(t, wp.array), np.concatenate([g.reshape(-1) for g in _gradients(t)])) for t in textures])
            tape.zero()
            assert not any(g.any() for t in textures for g in _gradients(t)), "tape.zero() must reset the gradients"
    finally:
        wt.set_num_threads(None)
    return grads[0], grads[1], grads[2], sum("texel_grad" in key and "blend" not in key for key in scatters)


def launches(monkeypatch) -> list[str]:
    """The keys of the kernels ``warptex._op`` launches from now on, forward (``launch``) and
    hand-written gradient (``scatter``; the lane kernel it may run instead is not listed), in order."""
    launched = []
    monkeypatch.setattr(_op, "scatter", lambda *a, **k: (launched.append(a[0].key), wt._launch.scatter(*a, **k)))
    monkeypatch.setattr(_op, "launch", lambda kernel, *a, **k: (launched.append(kernel.key), wt._launch.launch(kernel, *a, **k)))
    return launched


def _gradients(t) -> list[np.ndarray]:
    """Every level's gradient of a texture, or a parameter array's gradient."""
    if isinstance(t, wp.array):
        return [t.grad.numpy()]
    return [t.grad(k) for k in range(t.num_levels)]


def assert_same_gradients(hand_written: list, generated: list) -> None:
    """Equal to float rounding (sums in another order), each input against its own scale, and not
    trivially zero. A parameter's gradient sums a term per pixel in float32, with cancellation:
    the two ways then differ by about 1e-4 of it (as one way does between 1 and 2 threads)."""
    assert len(hand_written) == len(generated)
    assert max(np.abs(g).max() for _, g in generated) > 1
    for k, ((parameter, hand), (_, gen)) in enumerate(zip(hand_written, generated)):
        rtol = 1e-3 if parameter else 1e-5
        np.testing.assert_allclose(hand, gen, rtol=rtol, atol=2 * rtol * np.abs(gen).max(), err_msg=f"input {k}")


def splat_inputs(layer_data, map_data, tiling, other_grads: bool, *, plain: bool, height_blend=None, height_data=None, histogram=False):
    """Fresh inputs of a ``splat`` for :func:`texel_gradients_both_ways`: ``(layers, maps, kw,
    textures)``, the layers and splat maps with gradients, and ``kw`` the arrays to pass besides:
    ``tiling`` (with gradients when ``plain``: neither a stochastic method nor the histogram blend),
    ``sharpness`` (with gradients when ``other_grads``, which takes the generated adjoint), and
    where asked a ``height_blend`` transition array, separate ``heights`` from ``height_data`` and
    a hex ``stochastic`` with the layers' histogram. ``textures`` lists, in that order, the inputs
    whose gradients are compared (the histogram's texture in place of the layers)."""
    layers = wt.TextureArray(layer_data, requires_grad=True)
    maps = wt.TextureArray(map_data, mipmaps=False, requires_grad=True)
    kw = {"tiling": wp.array(tiling, dtype=float, requires_grad=plain), "sharpness": wp.array([4.0], dtype=float, requires_grad=other_grads)}
    textures = [layers, maps] + ([kw["tiling"]] if plain else [])
    if height_blend is not None:
        kw["height_blend"] = wp.array([height_blend], dtype=float, requires_grad=True)
        textures.append(kw["height_blend"])
    if height_data is not None:
        kw["heights"] = wt.TextureArray(height_data, requires_grad=True)
        textures.append(kw["heights"])
    if histogram:
        hist = wt.prepare_histogram(layers, requires_grad=True)
        kw["stochastic"] = wt.Stochastic("hex", histogram=hist)
        textures[0] = hist.texture
    return layers, maps, kw, textures
