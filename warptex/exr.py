"""OpenEXR files: linear float images with any channel names, read by layer (written by
:mod:`warptex.exr_writer`, band by band).

Channel names follow OpenEXR's layer convention: ``diffuse.R`` is channel ``R`` of layer
``diffuse`` (as Blender, Nuke and most renderers write them), a name without a dot belongs to the
default layer. Reading without naming channels picks one layer and orders its channels by their
suffix (R, G, B, A; X, Y, Z; U, V), never alphabetically.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import OpenEXR

from warptex._files import _checked_input_path

EXR_MAGIC = b"\x76\x2f\x31\x01"


def read_exr(path, channels: Sequence[str] | None = None, *, layer: str | None = None) -> tuple[np.ndarray, tuple[str, ...]]:
    """Read channels of an OpenEXR file.

    Pixels of the data window are returned (the display window is ignored);
    half and uint channels are converted to float32 (uint values above 2**24
    lose precision).

    Args:
        path: ``str`` or ``os.PathLike`` of the file.
        channels: Channel names to read, in that order (any number >= 1).
            Names may come from any part of a multi-part file whose size
            matches the first part's; the first part wins for duplicate
            names. If None, a layer of the first part is chosen (:func:`exr_layers`):
            the one ``layer`` names; else the default (unprefixed) layer when it
            has channels; else the only layer there is. Files with several named
            layers and no default one are refused, listing their layers. Within
            the layer: R,G,B (+A) if present, else Y (+A), else every channel in
            the order of its suffix (R, G, B, U, V, X, Y, Z, W, then others by
            name, A last) provided there are at most 4.
        layer: The layer to read, e.g. ``"diffuse"`` for ``diffuse.R``,
            ``diffuse.G``... (``""``: the unprefixed channels). With
            ``channels``, their names are taken inside this layer.

    Returns:
        ``(image, names)``: float32 array shaped [H, W, C] and the C channel
        names in order.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        ValueError: If the file cannot be decoded, requested channels are
            missing or differ in size, or the default choice would exceed 4
            channels.
        TypeError: If ``channels`` is not a sequence of str.
    """
    return _read_exr(_checked_input_path(path, "read_exr"), channels, layer, "read_exr")


def exr_channel_names(path) -> tuple[str, ...]:
    """Names of the channels in an EXR file's first part, read from its header only.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if it is not a readable OpenEXR file.
    """
    return _channel_names(_checked_input_path(path, "exr_channel_names"), "exr_channel_names")


# Header attributes every file has (OpenEXR writes them): not "extra" ones.
_STANDARD_ATTRIBUTES = {"channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
                        "screenWindowCenter", "screenWindowWidth", "type", "name", "version", "chunkCount", "tiles"}


def exr_attributes(path) -> dict:
    """The extra header attributes of an EXR file's first part (those beyond OpenEXR's standard
    ones, e.g. what :func:`write_exr`'s ``attributes`` wrote), read from its header only.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if it is not a readable OpenEXR file.
    """
    path = _checked_input_path(path, "exr_attributes")
    try:
        with OpenEXR.File(path, header_only=True) as exr:  # closing it empties its header: copy first
            return {k: v for k, v in exr.header().items() if k not in _STANDARD_ATTRIBUTES}
    except (RuntimeError, UnicodeDecodeError) as exc:
        raise ValueError(f"exr_attributes(): cannot decode '{path}' as an OpenEXR image: {exc}") from None


def _channel_names(path: str, func: str) -> tuple[str, ...]:
    try:
        with OpenEXR.File(path, header_only=True) as exr:
            return tuple(channel.name for channel in exr.header()["channels"])
    except (RuntimeError, UnicodeDecodeError) as exc:  # a corrupt header may hold a name that is not UTF-8
        raise ValueError(f"{func}(): cannot decode '{path}' as an OpenEXR image: {exc}") from None


def _read_exr(path: str, channels, layer, func: str, keep_half: bool = False) -> tuple[np.ndarray, tuple[str, ...]]:
    """:func:`read_exr` for ``func``; ``keep_half``: channels that are all half-float stay float16."""
    if layer is not None and not isinstance(layer, str):
        raise TypeError(f"{func}(): layer must be a str such as 'diffuse', got {type(layer).__name__}")
    if channels is not None:
        channels = _name_tuple(channels, func, "channels")
        if not channels:
            raise ValueError(f"{func}(): channels must name at least one channel")
        if layer:
            channels = tuple(f"{layer}.{name}" for name in channels)
    try:
        exr = OpenEXR.File(path, separate_channels=True)
        parts = exr.parts
        if not parts:  # OpenEXR reports a cut-short file by reading no parts
            raise RuntimeError("no readable image in it: truncated or corrupt")
        first = parts[0]
        available = dict(first.channels)
        if channels is None:
            channels = _default_exr_channels(available, layer, path, func)
        else:
            size = (first.height(), first.width())
            for part in parts[1:]:
                if (part.height(), part.width()) == size:
                    for name, channel in part.channels.items():
                        available.setdefault(name, channel)
    except (RuntimeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{func}(): cannot decode '{path}' as an OpenEXR image: {exc}") from exc
    missing = [name for name in channels if name not in available]
    if missing:
        raise ValueError(f"{func}(): channels {missing} not found in '{path}'; "
                         f"available channels: {sorted(available)}")
    planes = [available[name].pixels for name in channels]
    if any(p is None or p.ndim != 2 for p in planes):
        raise ValueError(f"{func}(): '{path}' holds deep or non-2D channel data, which is not supported")
    if len({p.shape for p in planes}) > 1:
        sizes = ", ".join(f"{name!r}: {p.shape}" for name, p in zip(channels, planes))
        raise ValueError(f"{func}(): channels of '{path}' differ in size (subsampled?): {sizes}")
    dtype = np.float16 if keep_half and all(p.dtype == np.float16 for p in planes) else np.float32
    return np.stack([p.astype(dtype, copy=False) for p in planes], axis=-1), channels


def _default_exr_channels(available: Mapping, layer: str | None, path: str, func: str) -> tuple[str, ...]:
    """The channels read when none are named: a layer chosen as :func:`read_exr` says, its channels
    in the order of their suffixes."""
    layers = _layers(available)
    if not layers:
        raise ValueError(f"{func}(): '{path}' has no channels")
    if layer is None:
        if "" in layers:
            layer = ""
        elif len(layers) == 1:
            layer = next(iter(layers))
        else:
            raise ValueError(f"{func}(): '{path}' holds several layers {sorted(layers)} and no default one; "
                             "choose one with layer= (warptex render: --texture-layer)")
    if layer not in layers:
        raise ValueError(f"{func}(): '{path}' has no layer {layer!r}; its layers: {_layer_list(layers)}")
    suffixes = layers[layer]
    full = (lambda s: f"{layer}.{s}") if layer else (lambda s: s)
    alpha = ("A",) if "A" in suffixes else ()
    if {"R", "G", "B"} <= suffixes.keys():
        chosen = ("R", "G", "B") + alpha
    elif "Y" in suffixes and not {"X", "Z"} <= suffixes.keys():  # luminance, unless it is X, Y, Z
        chosen = ("Y",) + alpha
    else:
        chosen = tuple(sorted(suffixes, key=_suffix_rank))
        if len(chosen) > 4:
            where = f"layer {layer!r} of '{path}'" if layer else f"'{path}'"
            raise ValueError(f"{func}(): {where} has {len(chosen)} channels {[full(s) for s in chosen]} and no R,G,B or Y; "
                             "pass channels= to choose which to read")
    return tuple(full(s) for s in chosen)


# Suffix order within a layer: colour, then UV, then position-like; unknown names by name; alpha last.
_SUFFIX_ORDER = ("R", "G", "B", "U", "V", "X", "Y", "Z", "W")


def _suffix_rank(suffix: str) -> tuple[int, str]:
    if suffix == "A":
        return (len(_SUFFIX_ORDER) + 1, suffix)
    return (_SUFFIX_ORDER.index(suffix) if suffix in _SUFFIX_ORDER else len(_SUFFIX_ORDER), suffix)


def _layers(names) -> dict[str, dict[str, str]]:
    """``{layer: {suffix: name}}``: a channel ``a.b.R`` is suffix ``R`` of layer ``a.b``; a name
    without a dot belongs to the default layer ``""``."""
    layers: dict[str, dict[str, str]] = {}
    for name in names:
        layer, _, suffix = name.rpartition(".")
        layers.setdefault(layer, {})[suffix] = name
    return layers


def _layer_list(layers) -> str:
    return ", ".join(repr(name) if name else "'' (the unprefixed channels)" for name in sorted(layers))


def exr_layers(path) -> dict[str, tuple[str, ...]]:
    """The layers of an EXR file's first part, ``{layer: channel names}``, from its header only: a
    channel ``diffuse.R`` belongs to layer ``"diffuse"``, one without a dot to the default layer ``""``.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if it is not a readable OpenEXR file.
    """
    path = _checked_input_path(path, "exr_layers")
    names = _channel_names(path, "exr_layers")
    return {layer: tuple(sorted(suffixes.values())) for layer, suffixes in sorted(_layers(names).items())}


def _name_tuple(names, func: str, arg: str) -> tuple[str, ...]:
    """Return channel names as a tuple of str; a lone str is rejected as ambiguous ('RGB' vs ('RGB',))."""
    try:
        result = None if isinstance(names, (str, bytes)) else tuple(names)
    except TypeError:
        result = None
    if result is None or not all(isinstance(name, str) for name in result):
        raise TypeError(f"{func}(): {arg} must be a sequence of str channel names such as ('R', 'G'), "
                        f"got {names!r}")
    return tuple(str(name) for name in result)
