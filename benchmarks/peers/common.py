"""Shared peer inputs: technique options and their defaults, data builders from warptex objects,
and the warptex call each technique corresponds to.

Only the builders and :func:`warptex_forward` import warptex (lazily); the peers themselves are
written from the formulas in the docstrings of ``kernels/``, not from warptex code.
"""

from __future__ import annotations

import numpy as np

#: Options of every technique with warptex's defaults (the peers read these keys from ``data``).
DEFAULTS = {
    "triplanar": {"tiling": 1.0, "sharpness": 4.0},
    "biplanar": {"tiling": 1.0, "sharpness": 8.0},
    "triplanar_aniso": {"tiling": 1.0, "sharpness": 4.0},
    "triplanar_normal": {"tiling": 1.0, "sharpness": 4.0, "strength": 1.0, "blend": "whiteout"},
    "splat4": {"tiling": 1.0},
    "splat8": {"tiling": 1.0},
    "hash4": {"seed": 0, "blend": (0.25, 0.75), "mirror": False},
    "cheap2": {"seed": 0, "blend": (0.2, 0.8), "mirror": False, "noise_frequency": 0.5, "noise_levels": 8.0},
    "hex": {"seed": 0, "contrast": 1.0},
}
GBUFFER_TECHNIQUES = ("triplanar", "biplanar", "triplanar_normal", "splat4", "splat8", "triplanar_aniso")
SPLAT_LAYERS = {"splat4": 4, "splat8": 8}


def texel_format(data: dict) -> str:
    """The texel format the peer's textures (and splat layers; maps stay float32) are to be stored
    in: ``data["format"]``, ``"float32"`` by default, ``"float16"`` where :attr:`Peer.formats` has it."""
    return data.get("format", "float32")


def uv_grads(data: dict) -> bool:
    """Whether ``forward_backward`` takes the UVs' gradients too (``data["uv_grads"]``, bilinear and
    trilinear), as well as the texels'."""
    return bool(data.get("uv_grads", False))


def options(data: dict, technique: str) -> dict:
    """The options of ``technique``: ``data``'s values over :data:`DEFAULTS`."""
    return {k: data.get(k, v) for k, v in DEFAULTS.get(technique, {}).items()}


def layer_tiling(data: dict, num_layers: int) -> np.ndarray:
    """Per-layer tiling of a splat, ``(L,)`` float32 (one value broadcasts)."""
    return np.broadcast_to(np.asarray(data.get("tiling", 1.0), np.float32).reshape(-1), (num_layers,)).copy()


def lod_kind(data: dict) -> str:
    """``"lod"`` (per-sample LOD), ``"derivatives"`` (``uv_dx``/``uv_dy``) or ``"none"`` (bilinear, level 0)."""
    if "lod" in data:
        return "lod"
    if "uv_dx" in data:
        return "derivatives"
    return "none"


def sample_lod(state: dict, from_derivatives):
    """The per-sample LOD of a sample technique's prepared ``state`` (its ``lod_kind``): the given
    LODs, ``from_derivatives(state["uv_dx"], state["uv_dy"])``, or ``None`` (bilinear on level 0)."""
    kind = state["lod_kind"]
    if kind == "lod":
        return state["lod"]
    if kind == "derivatives":
        return from_derivatives(state["uv_dx"], state["uv_dy"])
    return None


def sized_sample_lod(lod_from_derivatives):
    """:func:`sample_lod` for a backend whose ``lod_from_derivatives(size, dx, dy)`` takes level 0's
    ``(w, h)``: ``_sample_lod(state, size)``."""

    def _sample_lod(state: dict, size):
        return sample_lod(state, lambda dx, dy: lod_from_derivatives(size, dx, dy))

    return _sample_lod


def technique_bodies(*, bilinear, trilinear, planar, triplanar_normal, splat, stochastic) -> dict:
    """Every technique's body, ``body(state, textures) -> output``, by name (in the order of
    :data:`peers.TECHNIQUES`), for a backend's ``peers()``: ``planar(biplanar)`` builds the
    triplanar (``False``) and biplanar (``True``) bodies, ``stochastic(technique)`` those of hash4,
    cheap2 and hex."""
    return {
        "bilinear": bilinear,
        "trilinear": trilinear,
        "triplanar": planar(False),
        "biplanar": planar(True),
        "triplanar_normal": triplanar_normal,
        "splat4": splat,
        "splat8": splat,
        "hash4": stochastic("hash4"),
        "cheap2": stochastic("cheap2"),
        "hex": stochastic("hex"),
    }


# -- builders (warptex objects -> peer data) ---------------------------------------------------------


def texture_levels(texture) -> list[np.ndarray]:
    """Every mip level of a warptex ``Texture`` (``(h, w, C)``) or ``TextureArray`` (``(L, h, w, C)``)."""
    return [np.ascontiguousarray(texture.numpy(k), np.float32) for k in range(texture.num_levels)]


def sample_data(texture, uv, *, lod=None, uv_dx=None, uv_dy=None, **opts) -> dict:
    """Data of a sample technique (bilinear, trilinear, hash4, cheap2, hex) at ``uv`` ``(N, 2)``."""
    data = {"levels": texture_levels(texture), "uv": np.ascontiguousarray(uv, np.float32).reshape(-1, 2), **opts}
    if lod is not None:
        data["lod"] = np.ascontiguousarray(lod, np.float32).reshape(-1)
    if uv_dx is not None:
        data["uv_dx"] = np.ascontiguousarray(uv_dx, np.float32).reshape(-1, 2)
        data["uv_dy"] = np.ascontiguousarray(uv_dy, np.float32).reshape(-1, 2)
    return data


def gbuffer_data(gbuffer, *, texture=None, layers=None, maps=None, uv_set: str = "uv0", **opts) -> dict:
    """Data of a G-buffer technique: the G-buffer's arrays flattened to ``N = H·W`` samples, and
    ``texture``'s levels (triplanar, biplanar, normal map) or ``layers``' levels and ``maps``' level 0
    (splat)."""
    arrays = gbuffer.numpy()
    data = {k: np.ascontiguousarray(arrays[k], np.float32).reshape(-1, 3) for k in ("position", "normal", "position_dx", "position_dy")}
    data["mask"] = np.ascontiguousarray(arrays["mask"], np.float32).reshape(-1)
    if f"{uv_set}.uv" in arrays:
        for k in ("uv", "uv_dx", "uv_dy"):
            data[k] = np.ascontiguousarray(arrays[f"{uv_set}.{k}"], np.float32).reshape(-1, 2)
    if texture is not None:
        data["levels"] = texture_levels(texture)
    if layers is not None:
        data["layer_levels"] = texture_levels(layers)
    if maps is not None:
        data["maps"] = np.ascontiguousarray(maps.numpy(0) if hasattr(maps, "numpy") else maps, np.float32)
    data.update(opts)
    return data


def warptex_forward(technique: str, data: dict, *, texture=None, gbuffer=None, layers=None, maps=None, device=None):
    """The warptex call that ``technique``'s peers compute, with ``data``'s options (a ``wp.array``).

    Sample techniques take ``texture`` and ``data["uv"]`` (and its LOD source); G-buffer techniques
    take ``gbuffer`` and ``texture`` (or ``layers`` and ``maps`` for splat).
    """
    import warptex as wt

    opts = options(data, technique)
    if technique in GBUFFER_TECHNIQUES:
        if technique in SPLAT_LAYERS:
            return wt.splat(gbuffer, layers, maps, tiling=layer_tiling(data, layers.num_layers), projection="uv", device=device)
        if technique == "triplanar_normal":
            return wt.triplanar_normal(gbuffer, texture, tiling=opts["tiling"], sharpness=opts["sharpness"], strength=opts["strength"], blend=opts["blend"], device=device)
        fn = wt.biplanar if technique == "biplanar" else wt.triplanar
        sampler = wt.Sampler(filter="anisotropic") if technique == "triplanar_aniso" else None  # warptex only: no peer has it
        return fn(gbuffer, texture, tiling=opts["tiling"], sharpness=opts["sharpness"], sampler=sampler, device=device)
    kind = lod_kind(data)
    kw = {"lod": data["lod"]} if kind == "lod" else {"uv_dx": data["uv_dx"], "uv_dy": data["uv_dy"]} if kind == "derivatives" else {}
    if technique in ("bilinear", "trilinear"):
        sampler = wt.Sampler(filter="bilinear" if technique == "bilinear" else "auto")
        return wt.sample(texture, data["uv"], sampler=sampler, device=device, **({} if technique == "bilinear" else kw))
    return wt.stochastic(texture, data["uv"], wt.Stochastic(technique, **opts), device=device, **kw)
