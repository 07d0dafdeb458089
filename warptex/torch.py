"""warptex for PyTorch: every technique as a differentiable torch function.

::

    import torch
    import warptex.torch as wtt

    texture = torch.rand(256, 256, 3, requires_grad=True)   # [H, W, C], linear
    uv = torch.rand(4096, 2, requires_grad=True)
    colour = wtt.sample(texture, uv)                        # (4096, 3)
    colour.square().mean().backward()                       # texture.grad, uv.grad

The functions take the native functions' arguments (:func:`warptex.sample`, :func:`~warptex.stochastic`,
:func:`~warptex.triplanar`, :func:`~warptex.biplanar`, :func:`~warptex.triplanar_normal`, :func:`~warptex.biplanar_normal`,
:func:`~warptex.splat`, :func:`~warptex.splat_atlas`), with torch tensors where those take arrays:

- **textures** are float tensors, ``[H, W, C]`` for one texture or ``[L, H, W, C]`` for a texture
  array (``1 <= C <= 4``, linear), or uint8 / uint16 tensors of codes, divided by 255 / 65535 as
  :class:`~warptex.Texture` divides such arrays (read as float32 texels). Their mip chain is built inside the op, on the tape, so the
  gradients of every level a sample reads reach the tensor with no extra step;
- **per-sample inputs** (``uv``, ``uv_dx``, ``uv_dy``: ``(..., 2)``; ``lod``: uv's sample shape;
  ``layer``: int, uv's sample shape) and **parameters** (``tiling``, ``sharpness``, ``offsets``,
  ``height_blend``, the atlas ``weights``) are tensors or plain numbers;
- the **G-buffer** is a :class:`~warptex.GBuffer` (e.g. :meth:`GBuffer.from_arrays
  <warptex.GBuffer.from_arrays>` of another renderer's tensors), or the dict of tensors that
  :func:`gbuffer_tensors` makes of one (the form to pass inside code that ``torch.compile`` compiles). Its
  arrays are read in place and receive no gradients;
- options (:class:`~warptex.Sampler`, :class:`~warptex.Stochastic`, enums, strings) as natively.

Outputs are computed in float32 and returned in the floating dtype of the differentiable tensors
(torch's promotion: float64 textures and UVs give a float64 output); every gradient comes back in
its own tensor's dtype. Gradients flow through torch autograd to every differentiable tensor: texels, ``uv``, ``lod``,
``uv_dx``/``uv_dy``, ``tiling``, ``sharpness``, ``offsets``, splat maps, ``heights``,
``height_blend``, atlas ``weights`` and layers, and a histogram's Gaussianised texture
(:func:`prepare_histogram`). Outputs are the native call's bit for bit, gradients the native backward
pass's (to float rounding; tests/test_torch.py).

How it runs. Each call is one autograd node: in code that ``torch.compile`` compiles, the
``torch.library`` custom op ``warptex::technique``, which it sees as a single opaque node; in eager
mode the same forward and backward as a ``torch.autograd.Function``, without the op's dispatch
(~0.3 ms of a 1,024-UV call). Its forward runs the native function on zero-copy Warp
views of the tensors (on torch's current CUDA stream), under a ``wp.Tape`` when a gradient will be
needed; the tape is kept for the backward op (``warptex::technique_backward``), which runs it once
per ``backward()`` and returns the gradients as new tensors. The tape lives as long as the autograd
graph that holds it. Inputs must not be modified in place between the forward and the backward
(torch's own rule for saved tensors; the Warp views read them in place). A second-order gradient
(a gradient of the gradient) is not supported.

Requires PyTorch (``warptex._validate.TORCH_HINT`` says how to install it); the rest of warptex
never imports it.
"""

from __future__ import annotations

import functools
import inspect

try:
    import torch
except ImportError as err:
    from warptex._validate import TORCH_HINT

    raise ImportError(f"warptex.torch needs PyTorch, which is not installed: {TORCH_HINT}") from err

from warptex import _torch_op as _op
from warptex._torch_spec import TECHNIQUES, Technique, gbuffer_tensors, texture_tensor
from warptex.atlas import pack_atlas
from warptex.atlas import splat_atlas as _splat_atlas
from warptex.histogram import Histogram
from warptex.histogram import prepare_histogram as _prepare_histogram
from warptex.sampling import sample as _sample
from warptex.splat import splat as _splat
from warptex.stochastic import stochastic as _stochastic
from warptex.triplanar import biplanar as _biplanar
from warptex.triplanar import biplanar_normal as _biplanar_normal
from warptex.triplanar import triplanar as _triplanar
from warptex.triplanar import triplanar_normal as _triplanar_normal

__all__ = [
    "biplanar",
    "biplanar_normal",
    "gbuffer_tensors",
    "prepare_histogram",
    "sample",
    "splat",
    "splat_atlas",
    "stochastic",
    "triplanar",
    "triplanar_normal",
]


def bridge(native, *positional: str, rows: str = "gbuffer", channels: int | None = None, doc: str = ""):
    """Register ``native`` (a warptex technique) with the bridge and return its torch function.

    The function takes ``native``'s arguments (``device`` and ``out`` aside: the tensors' device is
    used, and the result is a new tensor), with
    tensors where ``native`` takes arrays, and returns a tensor ``(..., C)``: per sample of ``uv``
    (``rows="uv"``) or per G-buffer pixel (``"gbuffer"``), with ``channels`` channels or (``None``)
    those of its first texture. ``positional`` names ``native``'s positional arguments in order.
    Adding a technique to the bridge is this one call.
    """
    name = native.__name__
    TECHNIQUES[name] = Technique(native, positional, rows, channels)
    signature = inspect.Signature([p for p in inspect.signature(native).parameters.values() if p.name not in ("device", "out")], return_annotation=torch.Tensor)

    options = [p.name for p in signature.parameters.values() if p.kind is p.VAR_KEYWORD]
    leading = [p.name for p in signature.parameters.values() if p.kind is p.POSITIONAL_OR_KEYWORD]
    keywords = {p.name for p in signature.parameters.values() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    required = {p.name for p in signature.parameters.values() if p.name in keywords and p.default is p.empty}

    @functools.wraps(native)
    def function(*args, **kwargs):
        named = leading[: len(args)]
        arguments = {**dict(zip(named, args)), **kwargs}  # what bind() gives (a tenth of a small call), **options flattened
        if len(args) > len(leading) or not (options or kwargs.keys() <= keywords) or kwargs.keys() & {*named, *options} or not required <= arguments.keys():
            arguments = dict(signature.bind(*args, **kwargs).arguments)  # bind() says what is wrong
        for group in options:  # **options are passed on as keywords of their own
            arguments.update(arguments.pop(group, {}))
        if "out" in arguments:  # through **options: the native out= fills a Warp array
            raise TypeError(f"{name}() got an unexpected keyword argument 'out': the torch functions return a new tensor")
        return _op.call(name, arguments)

    function.__signature__ = signature
    function.__doc__ = f":func:`warptex.{name}` on torch tensors (module docstring). {doc}".rstrip()
    function.__module__ = __name__
    return function


def _splat_atlas_of_layers(gbuffer, layers, indices, weights, *, gutter: int = 4, columns: int | None = None, **options):
    """:func:`warptex.splat_atlas` with the atlas packed from ``layers`` (:func:`warptex.pack_atlas`) in
    the op, on its tape: the layers' gradients come through the atlas."""
    return _splat_atlas(gbuffer, pack_atlas(layers, gutter=gutter, columns=columns), indices, weights, **options)


_splat_atlas_of_layers.__name__ = "splat_atlas"

sample = bridge(_sample, "texture", "uv", rows="uv", doc="``texture`` ``[H, W, C]`` or ``[L, H, W, C]``, ``uv`` ``(..., 2)``; returns ``(..., C)``. "
                "Bilinear ``sample`` with ``\"clamp\"`` addressing is ``torch.nn.functional.grid_sample(..., align_corners=False, padding_mode=\"border\")`` "
                "at ``grid = (2u - 1, 1 - 2v)``.")  # fmt: skip
stochastic = bridge(_stochastic, "texture", "uv", rows="uv", doc="With a histogram (this module's :func:`prepare_histogram`) the texels read are its "
                    "Gaussianised texture, and the gradients go there.")  # fmt: skip
triplanar = bridge(_triplanar, "gbuffer", "texture", doc="Returns ``(H, W, C)``.")
biplanar = bridge(_biplanar, "gbuffer", "texture", doc="Returns ``(H, W, C)``.")
triplanar_normal = bridge(_triplanar_normal, "gbuffer", "normal_map", channels=3, doc="``normal_map`` as stored (``[0, 1]`` data). Returns unit world-space normals ``(H, W, 3)``.")
biplanar_normal = bridge(_biplanar_normal, "gbuffer", "normal_map", channels=3, doc="As :func:`triplanar_normal`, with biplanar weights.")
splat = bridge(_splat, "gbuffer", "layers", "splat_maps", doc="``layers`` ``[L, H, W, C]``, ``splat_maps`` ``[h, w, C]`` or ``[M, h, w, C]`` (read on "
               "level 0, no mips), ``heights`` ``[L, h, w, 1]``. Returns ``(H, W, C)``.")  # fmt: skip
splat_atlas = bridge(_splat_atlas_of_layers, "gbuffer", "layers", "indices", "weights", doc="``layers`` ``[L, H, W, C]`` are packed into an atlas "
                     "(``gutter``, ``columns``) inside the op; ``indices`` int ``[h, w, k]``, ``weights`` ``[h, w, k]``. Returns ``(H, W, C)``.")  # fmt: skip


def prepare_histogram(texture: torch.Tensor, *, lut_size: int = 4096, decorrelate: bool = False) -> Histogram:
    """:func:`warptex.prepare_histogram` of a texture tensor (``[H, W, C]`` or ``[L, H, W, C]``),
    for ``Stochastic(method="hex", histogram=...)`` in this module's functions.

    Returns a :class:`~warptex.Histogram` whose fields are tensors on ``texture``'s device:
    ``texture`` is the Gaussianised level 0 (shaped like the input; set ``requires_grad`` on it to
    fit it), ``lut``, ``basis`` and ``centre`` the transform. The transform is not differentiable.
    """
    func = "warptex.torch.prepare_histogram"
    t = texture_tensor(func, "texture", texture)
    native = _prepare_histogram(_op.native_texture(t.detach().cpu().numpy(), t.dim()), lut_size=lut_size, decorrelate=decorrelate)

    def tensor(a):
        return None if a is None else torch.as_tensor(a.numpy()).to(t.device)

    level0 = native.texture.numpy(0)
    return Histogram(
        texture=torch.as_tensor(level0).to(t.device),
        lut=tensor(native.lut),
        lut_size=native.lut_size,
        levels=native.levels,
        basis=tensor(native.basis),
        centre=tensor(native.centre),
        decorrelate=native.decorrelate,
    )
