"""G-buffers as multi-channel OpenEXR files.

Channels written by :func:`save_gbuffer` (all float32, so a round trip is bit-exact):

=====================  =========================================================
``P.X P.Y P.Z``        position (world space)
``N.X N.Y N.Z``        shading normal
``Ng.X Ng.Y Ng.Z``     geometric normal
``Z``                  depth along the camera's forward axis (``inf`` where empty)
``mask``               coverage, 1 or 0
``triangle``           triangle index, -1 where empty (exact below 2**24 faces)
``dPdx.X`` ... ``.Z``  position derivative per pixel along x; ``dPdy.*`` along y
``<set>.U <set>.V``    UV set ``<set>`` (``uv0`` first); ``<set>.dUdx``, ``<set>.dVdx``,
                       ``<set>.dUdy``, ``<set>.dVdy`` its derivatives;
                       ``<set>.T.X/Y/Z/W`` its tangent
=====================  =========================================================

:func:`load_gbuffer` also reads Blender's pass names, with or without a view-layer prefix
(``ViewLayer.Position.X``): ``Position``, ``Normal``, ``UV`` (``.U .V`` or ``.X .Y``) and ``Depth``
(``Depth.Z`` or ``Z``). Position and normal are required; missing optional channels get the
documented defaults.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import warp as wp

from warptex import io
from warptex.gbuffer import FIELDS, UV_FIELDS, GBuffer

_VEC = {wp.vec2: 2, wp.vec3: 3, wp.vec4: 4}
_NAMES = {
    "position": ("P.X", "P.Y", "P.Z"),
    "normal": ("N.X", "N.Y", "N.Z"),
    "geometric_normal": ("Ng.X", "Ng.Y", "Ng.Z"),
    "depth": ("Z",),
    "mask": ("mask",),
    "triangle": ("triangle",),
    "position_dx": ("dPdx.X", "dPdx.Y", "dPdx.Z"),
    "position_dy": ("dPdy.X", "dPdy.Y", "dPdy.Z"),
}
_UV_NAMES = {
    "uv": ("U", "V"),
    "uv_dx": ("dUdx", "dVdx"),
    "uv_dy": ("dUdy", "dVdy"),
    "tangent": ("T.X", "T.Y", "T.Z", "T.W"),
}
# Alternatives accepted on load, tried in order after warptex's own names (Blender's passes).
_ALIASES = {
    "position": [("Position.X", "Position.Y", "Position.Z")],
    "normal": [("Normal.X", "Normal.Y", "Normal.Z")],
    "depth": [("Depth.Z",), ("Depth.V",), ("Depth",)],
}
# Header attributes of a saved G-buffer: the float64 origin its positions are relative to, and its
# samples per pixel (GBuffer.origin, GBuffer.samples). Files without them: the world origin, 1.
ORIGIN_ATTRIBUTE = "warptexOrigin"
SAMPLES_ATTRIBUTE = "warptexSamples"
_BLENDER_UV = [("UV.U", "UV.V"), ("UV.X", "UV.Y")]
_BLENDER_PASSES = {"Position", "Normal", "UV", "Depth", "Combined", "Image", "Alpha", "Vector", "IndexOB", "IndexMA"}


def save_gbuffer(path: str | os.PathLike, gbuffer: GBuffer) -> None:
    """Write ``gbuffer`` to a float32 multi-channel EXR (channel names in the module docstring), atomically."""
    func = "save_gbuffer"
    if not isinstance(gbuffer, GBuffer):
        raise TypeError(f"{func}(): gbuffer must be a GBuffer, got {type(gbuffer).__name__}")
    if gbuffer.num_views is not None:
        raise ValueError(f"{func}(): the G-buffer is a batch of {gbuffer.num_views} views; save one at a time (gbuffer.view(k))")
    channels = gbuffer_channels(func, gbuffer)
    with _named(func), GBufferWriter(path, *gbuffer.resolution, uv_sets=list(gbuffer.uv_sets), origin=gbuffer.origin, samples=gbuffer.samples) as writer:
        writer.write(gbuffer, channels)


def gbuffer_channels(func: str, gbuffer: GBuffer) -> dict[str, np.ndarray]:
    """``{channel name: (H, W) float32}`` of an ``(H, W)`` G-buffer, as :func:`save_gbuffer` names them."""
    channels = {}
    h, w = gbuffer.resolution

    def put(field, names, values):
        values = np.asarray(values, np.float32)
        if values.size != h * w * len(names):
            raise ValueError(f"{func}(): the G-buffer is {h}x{w} but its {field} has shape {values.shape}")
        values = values.reshape(h, w, len(names))
        channels.update({name: values[..., i] for i, name in enumerate(names)})

    for name in FIELDS:
        put(name, _NAMES[name], getattr(gbuffer, name).numpy())
    for set_name, arrays in gbuffer.uv_sets.items():
        for name, suffixes in _UV_NAMES.items():
            put(f"{set_name} {name}", [f"{set_name}.{s}" for s in suffixes], arrays[name].numpy())
    return channels


class GBufferWriter:
    """:func:`save_gbuffer` band by band, for an image rasterised in tiles (:mod:`warptex.tiles`):
    :meth:`write` takes the G-buffer of the next rows. A context manager: the file appears when
    every row is written, and not at all on an error.

    Args:
        path: the ``.exr`` to write.
        height, width: the whole image's size.
        uv_sets: the names of the G-buffers' UV sets. origin, samples: as the G-buffers have them.
    """

    def __init__(self, path, height: int, width: int, *, uv_sets, origin, samples: int = 1):
        names = [n for field in FIELDS for n in _NAMES[field]] + [f"{s}.{x}" for s in uv_sets for suffixes in _UV_NAMES.values() for x in suffixes]
        attributes = {ORIGIN_ATTRIBUTE: np.asarray(origin, np.float64), SAMPLES_ATTRIBUTE: int(samples)}
        self._names = names
        self._writer = io.ExrWriter(path, height, width, names, attributes=attributes)

    def write(self, gbuffer: GBuffer, channels: dict | None = None) -> None:
        """Append the rows of ``gbuffer`` (an ``(n, W)`` G-buffer of the image's next rows)."""
        channels = gbuffer_channels("GBufferWriter.write", gbuffer) if channels is None else channels
        self._writer.write({name: channels[name] for name in self._names})

    def __enter__(self) -> "GBufferWriter":
        return self

    def __exit__(self, kind, error, trace) -> None:
        self._writer.__exit__(kind, error, trace)


def load_gbuffer(path: str | os.PathLike, *, layer: str | None = None, device=None) -> GBuffer:
    """Read a G-buffer EXR written by :func:`save_gbuffer`, Blender, or another tool using either naming.

    Args:
        path: the EXR file.
        layer: view-layer prefix to read (e.g. ``"ViewLayer"``) when the file holds several;
            ``None`` accepts channels with or without any single prefix.
        device: Warp device for the arrays.

    Defaults for missing optional channels: geometric normal = normal; depth = ``inf`` where the
    mask is 0, else 1; mask = 1 where depth is finite and below 1e9 (Blender's background is
    1e10), or everywhere without depth; triangle = 0 on covered pixels and -1 elsewhere;
    derivatives = 0 (so sampling uses mip level 0); tangents = 0.

    Raises:
        ValueError: the file is not a readable EXR, or lacks position or normal channels (the
            message names the channels it looked for and lists those present).
    """
    func = "load_gbuffer"
    with_names = _channel_table(func, path, layer)
    resolution = next(iter(with_names.values())).shape

    def find(candidates):
        for names in candidates:
            if all(n in with_names for n in names):
                return np.stack([with_names[n] for n in names], axis=-1)
        return None

    data = {}
    for name in FIELDS:
        data[name] = find([_NAMES[name], *_ALIASES.get(name, [])])
    for required in ("position", "normal"):
        if data[required] is None:
            wanted = " or ".join(str(list(n)) for n in [_NAMES[required], *_ALIASES[required]])
            raise ValueError(
                f"{func}(): '{os.fspath(path)}' has no {required} channels (looked for {wanted}); "
                f"it has {sorted(with_names)}"
            )
    depth = data["depth"][..., 0] if data["depth"] is not None else None
    if data["mask"] is None:
        covered = np.isfinite(depth) & (depth < 1e9) if depth is not None else np.ones(resolution, bool)
        data["mask"] = covered.astype(np.float32)[..., None]
    covered = data["mask"][..., 0] > 0.5
    if depth is None:
        data["depth"] = np.where(covered, 1.0, np.inf).astype(np.float32)[..., None]
    if data["geometric_normal"] is None:
        data["geometric_normal"] = data["normal"]
    if data["triangle"] is None:
        data["triangle"] = np.where(covered, 0, -1)[..., None]
    for name in ("position_dx", "position_dy"):
        if data[name] is None:
            data[name] = np.zeros((*resolution, 3), np.float32)

    device = wp.get_device(device)
    arrays = {name: _to_warp(data[name], dtype, device) for name, dtype in FIELDS.items()}
    uv_sets = {}
    for set_name in _uv_set_names(with_names):
        found = {k: find([[f"{set_name}.{s}" for s in suffixes]]) for k, suffixes in _UV_NAMES.items()}
        if found["uv"] is None:  # uv0 from Blender's UV pass
            found["uv"] = find(_BLENDER_UV)
        uv_sets[set_name] = {
            k: _to_warp(found[k] if found[k] is not None else np.zeros((*resolution, _VEC[t]), np.float32), t, device)
            for k, t in UV_FIELDS.items()
        }
    with _named(func):
        attributes = io.exr_attributes(path)
    origin, samples = attributes.get(ORIGIN_ATTRIBUTE, np.zeros(3)), attributes.get(SAMPLES_ATTRIBUTE, 1)
    try:
        return GBuffer(**arrays, uv_sets=uv_sets, origin=origin, samples=int(samples))
    except (TypeError, ValueError) as err:
        raise ValueError(f"{func}(): '{os.fspath(path)}' has a bad {ORIGIN_ATTRIBUTE} or {SAMPLES_ATTRIBUTE}: {err}") from None


def _channel_table(func: str, path, layer: str | None) -> dict[str, np.ndarray]:
    """Every channel of the file as ``[H, W]`` float32, keyed by its name without the view-layer prefix."""
    with _named(func):
        planes, names = io.read_exr(path, channels=io.exr_channel_names(path))
    # Blender names channels "<view layer>.<pass>.<component>".
    prefixes = {n.rsplit(".", 2)[0] for n in names if n.count(".") >= 2 and n.split(".")[-2] in _BLENDER_PASSES}
    if layer is None:
        if len(prefixes) > 1:
            raise ValueError(f"{func}(): '{os.fspath(path)}' holds several view layers {sorted(prefixes)}; pass layer=")
        layer = next(iter(prefixes), None)
    elif layer not in prefixes:
        raise ValueError(f"{func}(): '{os.fspath(path)}' has no view layer {layer!r}; it has {sorted(prefixes) or 'none'}")
    strip = f"{layer}." if layer else "\0"
    return {(n[len(strip) :] if n.startswith(strip) else n): planes[..., i] for i, n in enumerate(names)}


@contextmanager
def _named(func: str) -> Iterator[None]:
    """Errors of the :mod:`warptex.io` calls inside, reported as ``func``'s own: ``"read_exr(): x"``
    becomes ``"load_gbuffer(): x"`` (same exception type)."""
    try:
        yield
    except (OSError, ValueError, TypeError) as err:
        message = f"{func}(): " + re.sub(r"^\w+\(\): ", "", str(err))
        try:
            renamed = type(err)(message)
        except TypeError:  # an exception type that takes other arguments
            renamed = ValueError(message)
        raise renamed from err


def _uv_set_names(table: dict[str, np.ndarray]) -> list[str]:
    """UV sets present: warptex's ``<set>.U``/``<set>.V`` pairs, and Blender's ``UV`` pass as ``uv0``."""
    sets = sorted(n[:-2] for n in table if n.endswith(".U") and n[:-2] + ".V" in table and n[:-2] != "UV")
    if "uv0" not in sets and any(all(n in table for n in names) for names in _BLENDER_UV):
        sets.insert(0, "uv0")
    return sets


def _to_warp(values: np.ndarray, dtype, device) -> wp.array:
    values = np.ascontiguousarray(values, np.float32)
    if dtype == wp.int32:
        return wp.array(values[..., 0].astype(np.int32), dtype=wp.int32, device=device)
    if dtype == wp.float32:
        return wp.array(values[..., 0], dtype=wp.float32, device=device)
    return wp.array(values, dtype=dtype, device=device)
