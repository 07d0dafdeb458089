"""Finite-difference checks of parameters shared by every pixel (tiling, sharpness, transition...).

Such a parameter's gradient is a sum over all pixels, and filtering has slope jumps (bilinear on
texel lines, trilinear at level boundaries, height blends at their max/ReLU switches), so a
central difference of the whole image is off wherever a pixel's step crosses one. Pixels whose
one-sided differences disagree are given zero output weight before the analytic gradient and the
central difference are compared (at least ``min_kept`` of the pixels must remain, so the check
cannot pass by leaving everything out).
"""

import numpy as np


def check_parameter_gradient(render, gradient, value, r, step, *, rtol=2e-3, atol=2e-3, min_kept=0.9, label=""):
    """Check every component of ``value`` (a float64 array).

    Args:
        render: ``render(value) -> [H, W, C]`` output for a parameter value.
        gradient: ``gradient(value, r) -> array like value``: the analytic gradient of
            ``Σ r · render(value)`` from a backward pass.
        value: the parameter at which to check.
        r: ``[H, W, C]`` output weights.
        step: finite-difference step.
    """
    value = np.asarray(value, np.float64)
    for index in np.ndindex(value.shape):
        outs = []
        for delta in (-step, 0.0, step):
            v = value.copy()
            v[index] += delta
            outs.append(np.asarray(render(v), np.float64))
        minus, centre, plus = outs
        backward, forward = (centre - minus) / step, (plus - centre) / step
        central = (plus - minus) / (2 * step)
        smooth = (np.abs(forward - backward) <= 1e-2 * (1 + np.abs(central))).all(axis=-1)
        assert smooth.mean() >= min_kept, f"{label}{list(index)}: too few smooth pixels ({smooth.mean():.2f})"
        kept = (r * smooth[..., None]).astype(np.float32)
        analytic = np.asarray(gradient(value, kept), np.float64)[index]
        np.testing.assert_allclose(analytic, (central * kept).sum(), rtol=rtol, atol=atol, err_msg=f"{label}{list(index)}")
