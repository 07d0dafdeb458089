"""The adapter to Warp's internals (``warptex/_warp.py``) against the installed Warp release.

warptex reaches into Warp in these few places only; if a Warp release changes them, these tests
say so before the threaded backward passes or the tape records go wrong.
"""

import numpy as np
import pytest
import warp as wp

import warptex as wt
from warptex import _op, _warp
from warptex.kernels import projection as kp
from warptex.kernels import sampling as ks


def test_active_tape_is_the_tape_being_recorded():
    assert _warp.active_tape() is None
    for _ in range(2):
        tape = wp.Tape()
        with tape:
            assert _warp.active_tape() is tape
        assert _warp.active_tape() is None


def test_struct_fields_and_a_new_struct_of_the_same_kind():
    smp = ks.SamplerArgs()
    smp.filter, smp.address, smp.lod_bias = 2, 1, 0.5
    fields = _warp.struct_fields(smp)
    assert list(fields) == ["filter", "address", "border", "lod_bias", "min_lod", "max_lod", "max_aniso"]
    assert fields["filter"] == 2 and fields["lod_bias"] == 0.5
    copy = _warp.struct_like(smp)
    assert type(copy) is type(smp) and copy.filter == 0
    for name, value in fields.items():
        setattr(copy, name, value)
    assert _warp.struct_fields(copy)["address"] == 1

    proj = kp.ProjectionArgs()
    proj.tiling = wp.array([2.0], dtype=float, requires_grad=True)
    assert _warp.struct_fields(proj)["tiling"] is proj.tiling  # arrays come back as they were set

    args = ks.SampleArgs()  # a struct nested in a struct, scalars, a vector (SamplerArgs.border)
    args.tex = wt.Texture(np.ones((4, 4, 4), np.float32)).view
    found = list(_warp.struct_arrays(args))
    assert [p for p, _ in found] == [f"tex.{n}" for n, v in _warp.struct_fields(args.tex).items() if isinstance(v, wp.array)]
    assert all(a is getattr(args.tex, p.split(".")[1]) for p, a in found)
    assert list(_warp.struct_arrays(args.smp)) == []  # no arrays (a vector, scalars)
    assert [p for p, _ in _warp.struct_arrays(args, (wp.float32,))] == ["tex.texels"]  # vec4: float; the level tables: int32
    assert [p for p, _ in _warp.struct_arrays(args, (wp.int32,))] == [p for p, _ in found if p != "tex.texels"]
    assert _warp.field_type(args, "tex") is ks.TextureView and _warp.field_type(args.tex, "num_levels") is wp.int32


def test_threaded_generated_adjoint_accumulates_struct_array_gradients(rng):
    """The private accumulators that a split backward pass puts into struct fields (through the
    adapter) reach the real gradient: a generated adjoint over two threads equals one thread."""
    img = rng.random((16, 16, 2), dtype=np.float32)
    uv = rng.uniform(-2, 2, (70000, 2)).astype(np.float32)
    weights = rng.normal(size=(70000, 2)).astype(np.float32)
    grads = []
    for threads in (1, 2):
        wt.set_num_threads(threads)
        try:
            tex = wt.Texture(img, requires_grad=True)
            tape = wp.Tape()
            with tape, _op.force_generated_adjoint():
                out = wt.sample(tex, uv, lod=0.6)
            out.grad.assign(weights)
            tape.backward()
            grads.append(np.concatenate([tex.grad(k).ravel() for k in range(tex.num_levels)]))
        finally:
            wt.set_num_threads(None)
    assert np.abs(grads[0]).max() > 1
    np.testing.assert_allclose(grads[1], grads[0], rtol=1e-5, atol=1e-5 * np.abs(grads[0]).max())


@wp.kernel
def _scaled(values: wp.array(dtype=float), scale: float, offset: wp.vec2, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = values[i] * scale + offset[0] - offset[1]


def test_a_kept_cpu_launch_called_straight_runs_as_wp_launch(rng):
    """``kept_call`` of a CPU ``wp.Launch`` calls the kernel's entry point with the launch's
    parameters (Warp's CPU calling convention), and :meth:`set` points one elsewhere."""
    values = wp.array(rng.random(37, dtype=np.float32))
    first, second = wp.zeros(37, dtype=float), wp.zeros(37, dtype=float)
    cmd = wp.launch(_scaled, dim=37, inputs=[values, 2.5, wp.vec2(0.25, 1.0), first], device="cpu", record_cmd=True)
    call = _warp.kept_call(cmd)
    assert isinstance(call, _warp.CpuLaunch)
    want = values.numpy() * np.float32(2.5) + np.float32(0.25) - np.float32(1.0)
    call()
    np.testing.assert_array_equal(first.numpy(), want)
    call.set(3, _warp.array_struct(second, (37,)))
    call()
    np.testing.assert_array_equal(second.numpy(), want)
    assert not _warp.cpu_capturing()


@wp.struct
class _Samples:
    values: wp.array(dtype=float)
    scale: float


@wp.kernel
def _scaled_struct(args: _Samples, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = args.values[i] * args.scale


@pytest.mark.parametrize("straight", [True, False])
def test_a_kept_launchs_struct_field_points_elsewhere(rng, straight):
    """:meth:`field` of a kept launch, straight (:class:`~warptex._warp.CpuLaunch`) or through
    ``wp.Launch`` (``_LaunchCall``), gives a struct parameter's array that a plan points at another
    array of the same layout (``warptex._plan``): the next call reads that one, and the struct
    the launch was made with is left as it was."""
    values, others = (wp.array(rng.random(29, dtype=np.float32)) for _ in range(2))
    out = wp.zeros(29, dtype=float)
    args = _Samples()
    args.values, args.scale = values, 3.0
    cmd = wp.launch(_scaled_struct, dim=29, inputs=[args, out], device="cpu", record_cmd=True)
    call = _warp.kept_call(cmd) if straight else _warp._LaunchCall(cmd)
    assert call.field(0, "values").data == values.ptr
    field = call.field(0, "values")
    field.data = others.ptr
    call()
    np.testing.assert_array_equal(out.numpy(), others.numpy() * np.float32(3.0))
    assert call.field(0, "values").data == others.ptr and args._ctype.values.data == values.ptr
