"""The hand-written gradient of normal mapping's second step (the normal made from stored samples,
``kernels.normal_blend.normal_from_samples_grad``), on its own, against Warp's generated adjoint of
the same body and against central differences, over every blend, channel count, green flip,
strength, mirror fix and object-space matrix, with the edge cases its branches hold: texels that
decode to zero, a blend of zero (the surface normal is kept: no gradient), blends past
~1.8e19 (scaled down before they are normalised), zero weights, uncovered pixels and zero normals.
"""

import functools
import itertools

import numpy as np
import pytest
import warp as wp

from warptex.kernels import normal_blend as kt
from warptex.kernels.family import forward_kernel
from warptex.kernels.lanes import LANES
from warptex.kernels.normals import BLEND_RNM, BLEND_UDN, BLEND_WHITEOUT

N = 512
BLENDS = {"whiteout": BLEND_WHITEOUT, "udn": BLEND_UDN, "rnm": BLEND_RNM}


@functools.cache
def _generated():
    """The same body with Warp's generated adjoint (the product has none: it needs none)."""
    return forward_kernel(kt.normal_from_samples, kt.NormalBlendArgs, kt.StoredSamples, wp.array2d(dtype=float), module="test_normal_blend_generated", name="normal_blend_generated", enable_backward=True)


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q


def _inputs(seed: int, matrix: str, n: int = N):
    """Per-pixel inputs (float32 numpy) and the normal matrices: ``identity``, ``object`` (a
    rotation and an anisotropic scale) or ``huge`` (every blend past ~1.8e19 in world space)."""
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=(n, 3))
    normal[::17] *= np.array([1.0, 1e-6, 0.0])  # a component at or near 0: the mirror fix's sign
    weights = rng.random((n, 3))
    weights[rng.random((n, 3)) < 0.3] = 0.0  # projections that are not read
    normal[5], weights[5] = 0.0, 0.0  # a zero normal, whose weights the first step stores as 0
    samples = rng.random((n, 3, 4))
    samples[7, :, :3] = 0.5  # three-channel texels that decode to zero (strength aside: z = 0)
    normal[9], weights[9], samples[9, 2, :3] = (0.0, 0.0, 2.0), (0.0, 0.0, 1.0), 0.5  # whiteout: a blend of 0, the surface normal kept
    mask = np.ones(n)
    mask[::11] = 0.0
    to_object = to_world = np.eye(3)
    if matrix != "identity":
        m = _rotation(rng) @ np.diag([0.5, 2.0, 1.3]) @ _rotation(rng)
        to_object, to_world = np.linalg.inv(m).T, m.T
        if matrix == "huge":
            to_world = to_world * 1e20
    return [a.astype(np.float32) for a in (normal, weights, samples, mask)], (to_object, to_world)


def _structs(inputs, matrices, blend, channels, flip_green, strength, mirror_fix, samples=None):
    normal, weights, stored, mask = inputs
    args = kt.NormalBlendArgs()
    args.proj.normal_to_object = wp.mat33(*matrices[0].astype(np.float32).reshape(-1))
    args.proj.normal_to_world = wp.mat33(*matrices[1].astype(np.float32).reshape(-1))
    args.proj.mirror_fix = mirror_fix
    args.proj.tiling, args.proj.sharpness, args.proj.offsets = wp.empty(0, dtype=float), wp.empty(0, dtype=float), wp.empty((0, 2), dtype=float)  # not read
    args.normal_map.channels, args.normal_map.strength, args.normal_map.flip_green, args.normal_map.blend = channels, strength, flip_green, BLENDS[blend]
    pixels = kt.StoredSamples()
    pixels.normal = wp.array(normal, dtype=wp.vec3)
    pixels.mask = wp.array(mask, dtype=float)
    pixels.weights = wp.array(weights, dtype=wp.vec3)
    pixels.samples = samples if samples is not None else wp.array(stored, dtype=wp.vec4)
    return args, pixels


def _forward(kernel, args, pixels, per_index: int = 1) -> wp.array:
    n = pixels.mask.shape[0]
    out = wp.zeros((n, 3), dtype=float, requires_grad=True)
    wp.launch(kernel, dim=-(-n // per_index), inputs=[args, pixels, 0], outputs=[out])
    return out


def _hand_written(args, pixels, adj: np.ndarray, kernel=None, per_index: int = 1) -> np.ndarray:
    n = pixels.mask.shape[0]
    grads = kt.StoredSampleGrads()
    grads.samples = wp.array(np.full((n, 3, 4), 0.25, np.float32), dtype=wp.vec4)  # added into
    grads.sharpness = wp.empty(0, dtype=float)  # not needed
    wp.launch(kernel or kt.normal_from_samples_kernels().texel_grad, dim=-(-n // per_index), inputs=[args, pixels, 0, grads, wp.array(adj, dtype=float)])
    return grads.samples.numpy() - 0.25


def _same_bits(a: np.ndarray, b: np.ndarray) -> None:
    """The same floats bit for bit, NaN wherever either is (any payload: which operand's NaN an
    operation passes on is the compiler's choice of operand order)."""
    nan = np.isnan(a)
    np.testing.assert_array_equal(nan, np.isnan(b))
    np.testing.assert_array_equal(a[~nan].view(np.uint32), b[~nan].view(np.uint32))


CONFIGURATIONS = list(itertools.product(BLENDS, (2, 3, 4), (0, 1)))


@pytest.mark.parametrize(("blend", "channels", "flip_green"), CONFIGURATIONS)
@pytest.mark.parametrize("matrix", ["identity", "object", "huge"])
def test_hand_written_gradient_equals_the_generated_adjoint(blend, channels, flip_green, matrix):
    inputs, matrices = _inputs(1, matrix)
    adj = np.random.default_rng(2).normal(size=(N, 3)).astype(np.float32)
    for strength, mirror_fix in ((1.0, 1), (0.6, 0), (2.5, 1)):
        samples = wp.array(inputs[2], dtype=wp.vec4, requires_grad=True)
        args, pixels = _structs(inputs, matrices, blend, channels, flip_green, strength, mirror_fix, samples)
        tape = wp.Tape()
        with tape:
            out = _forward(_generated(), args, pixels)
        out.grad.assign(adj)
        tape.backward()
        generated = samples.grad.numpy()
        hand = _hand_written(args, pixels, adj)
        np.testing.assert_array_equal(_forward(kt.normal_from_samples_kernels().forward, args, pixels).numpy(), out.numpy())
        assert np.abs(hand).max() > 0
        scale = np.abs(generated).max()
        np.testing.assert_allclose(hand, generated, rtol=1e-5, atol=1e-6 * scale, err_msg=f"strength {strength}, mirror fix {mirror_fix}")
        assert not hand[inputs[3] == 0].any() and not hand[5].any(), "uncovered pixels and a zero normal have no gradient"
        assert not hand[inputs[1] == 0].any(), "a projection that is not read has no gradient"
        assert not hand[..., 3].any(), "the fourth channel is not read"
        if channels >= 3:
            assert not hand[7].any() and not hand[9].any(), "texels that decode to zero have none"
            if blend == "whiteout" and matrix == "identity":
                np.testing.assert_array_equal(out.numpy()[9], (0.0, 0.0, 1.0))  # the surface normal


@pytest.mark.parametrize(("blend", "channels", "flip_green"), CONFIGURATIONS)
def test_hand_written_gradient_matches_central_differences(blend, channels, flip_green):
    """Along random directions of every sample, in float64 sums of the float32 outputs, on texels
    where the normal is smooth (a normal map's usual range: slopes within ±0.6, blue near 1; not
    where a two-channel map's rebuilt ``z`` meets 0, nor texels that decode to 0)."""
    inputs, matrices = _inputs(4, "object")
    rng = np.random.default_rng(5)
    inputs[2][...] = np.concatenate([rng.uniform(0.2, 0.8, (N, 3, 2)), rng.uniform(0.8, 1.0, (N, 3, 2))], -1)
    adj = rng.normal(size=(N, 3))
    strength, mirror_fix = 0.8, 1
    args, pixels = _structs(inputs, matrices, blend, channels, flip_green, strength, mirror_fix)
    hand = _hand_written(args, pixels, adj.astype(np.float32)).astype(np.float64)
    kernel = kt.normal_from_samples_kernels().forward
    step = 1e-3

    def loss(samples: np.ndarray) -> float:
        _, shifted = _structs(inputs, matrices, blend, channels, flip_green, strength, mirror_fix, wp.array(samples.astype(np.float32), dtype=wp.vec4))
        return float((_forward(kernel, args, shifted).numpy().astype(np.float64) * adj).sum())

    for _ in range(3):
        direction = rng.normal(size=inputs[2].shape)
        fd = (loss(inputs[2] + step * direction) - loss(inputs[2] - step * direction)) / (2 * step)
        np.testing.assert_allclose((hand * direction).sum(), fd, rtol=2e-3, atol=2e-3)


@pytest.mark.parametrize(("blend", "channels", "flip_green"), CONFIGURATIONS)
def test_lanes_give_the_one_pixel_bits(blend, channels, flip_green):
    """The CPU lanes of the step (``normal_lanes.stored_normals_lane`` and ``_grad_lane``): the
    one-pixel kernels' normals and gradients, bit for bit, over a count that ends in a part lane
    (the gradient added into a non-zero array, as the first step's pass leaves none)."""
    kernels = kt.normal_from_samples_kernels()
    n = 16 * 31 + 5
    for matrix, (strength, mirror_fix) in itertools.product(("identity", "object", "huge"), ((1.0, 1), (0.6, 0), (2.5, 1))):
        inputs, matrices = _inputs(6, matrix, n)
        inputs[0][20:24] = [(3e19, -1e-30, 2e19), (2e19, -3e19, -1e19), (np.inf, 0.0, 1.0), (np.nan, 1.0, 0.0)]  # past ~1.8e19, non-finite
        args, pixels = _structs(inputs, matrices, blend, channels, flip_green, strength, mirror_fix)
        adj = np.random.default_rng(7).normal(size=(n, 3)).astype(np.float32)
        lanes = _forward(kernels.lanes, args, pixels, LANES).numpy()
        _same_bits(lanes, _forward(kernels.forward, args, pixels).numpy())
        hand = _hand_written(args, pixels, adj)
        _same_bits(_hand_written(args, pixels, adj, kernels.texel_grad_lanes, LANES), hand)
        assert np.nanmax(np.abs(hand)) > 0 and np.nanmax(np.abs(lanes)) > 0
