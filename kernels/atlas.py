"""The atlas + index-map variant of splat-map terrain texturing.

Instead of ``L`` layer textures and ``ceil(L / 4)`` splat maps, the layers are packed into one
*atlas* texture, and per splat texel an *index map* names the ``k`` layers that matter there while
a *weight map* holds their weights (both exported offline from the splat maps). A pixel then reads
``k`` atlas tiles however many layers there are.

Atlas layout (:class:`AtlasLayout`): layer ``l`` sits in grid cell ``(row, col) = (l // columns,
l % columns)``, rows counted from the top of the atlas image. A cell is ``tile_height + 2·gutter``
by ``tile_width + 2·gutter`` texels: the layer in the middle, surrounded by ``gutter`` texels of
its own *wrapped* content, so filtering across a tile edge reads the layer's wrapped neighbours and
never the next tile. Level-0 atlas texel ``(row·(th + 2g) + y, col·(tw + 2g) + x)`` holds layer
texel ``((y - g) mod th, (x - g) mod tw)`` for ``0 <= y < th + 2g``, ``0 <= x < tw + 2g``.

Sampling a layer at UV ``uv``: ``f = frac(uv)`` (exact, see ``reduce_coord``), then the atlas
texel coordinates ``x = col·(tw + 2g) + g + f.x·tw``, ``y = row·(th + 2g) + g + (1 - f.y)·th``
(row 0 on top, as for every texture), i.e. atlas UV ``(x / W_atlas, 1 - y / H_atlas)``. The UV
derivatives are scaled by the same chain rule, so the LOD is the pixel footprint in *tile* texels,
exactly the LOD the layer would get as a texture of its own.

Why the LOD must be clamped: when ``th``, ``tw`` and ``g`` are divisible by ``2^ℓ``, atlas level
``ℓ`` (box-filtered, sizes halved) is the grid of every layer's own level ``ℓ`` with a gutter of
``g / 2^ℓ`` texels, still of wrapped content. Bilinear filtering inside a tile reads at most one
texel beyond the tile, so it is exact while ``g / 2^ℓ >= 1``. Past that level a coarse texel
averages texels of two tiles (and tile edges stop falling on texel edges), and colour bleeds
across tiles: the grey seams of naively mipmapped atlases. The safe levels are ``ℓ <= v2(g), v2(th), v2(tw)``
(``v2`` = the number of times 2 divides the int), so ``ℓ_max <= log2(g)``; the sampler clamps the
LOD (after bias, before trilinear blending) to that ``ℓ_max``, which the Python side computes.
"""

import warp as wp

from . import inlined, specialised
from .family import Kernels, family, pixel_kernels
from .filters import sample_lod, sample_lod_outlined
from .footprint import footprint_mean, footprint_taps, footprint_uv, uv_footprint
from .native import use
from .texels import ADDRESS_WRAP, SamplerArgs, TextureView, fetch, reduce_coord, write_channels

MODULE = use("warptex.atlas")

MAX_ENTRIES = wp.constant(4)  # the most index-map entries (k) per texel: an RGBA index map
ATLAS_EPS = wp.constant(1.0e-20)


@wp.struct
class AtlasLayout:
    """Where the tiles lie in the atlas (all in level-0 texels)."""

    tile_width: wp.int32
    tile_height: wp.int32
    gutter: wp.int32
    columns: wp.int32
    num_tiles: wp.int32


@wp.kernel(module=MODULE)
def pack_kernel(layers: TextureView, layout: AtlasLayout, wrap: SamplerArgs, atlas: wp.array2d(dtype=wp.vec4)):
    """Write every layer's cell (tile + wrapped gutter) into level 0 of the atlas.

    Launched over ``(L, th + 2g, tw + 2g)``; ``wrap`` is a wrap-addressing sampler, so ``fetch``
    wraps the gutter indices. Recorded on a tape, the backward pass adds every atlas texel's
    gradient (gutter copies included) to the layer texel it was copied from.
    """
    layer, y, x = wp.tid()
    g = layout.gutter
    row = layer // layout.columns
    col = layer % layout.columns
    ay = row * (layout.tile_height + 2 * g) + y
    ax = col * (layout.tile_width + 2 * g) + x
    atlas[ay, ax] = fetch(layers, layer, 0, x - g, y - g, wrap)


@wp.func
def tile_uv(atlas: TextureView, layout: AtlasLayout, layer: wp.int32, uv: wp.vec2) -> wp.vec2:
    """The atlas UV of layer ``layer`` at layer UV ``uv``, wrapped into the tile (module docstring)."""
    fx = reduce_coord(uv[0], ADDRESS_WRAP)
    fy = reduce_coord(uv[1], ADDRESS_WRAP)
    g = layout.gutter
    row = layer // layout.columns
    col = layer % layout.columns
    x = float(col * (layout.tile_width + 2 * g) + g) + fx * float(layout.tile_width)
    y = float(row * (layout.tile_height + 2 * g) + g) + (1.0 - fy) * float(layout.tile_height)
    return wp.vec2(x / float(atlas.level_width[0]), 1.0 - y / float(atlas.level_height[0]))


def _sample_tile(sample, name: str):
    def sample_tile(
        atlas: TextureView, layout: AtlasLayout, layer: wp.int32, uv: wp.vec2, uv_dx: wp.vec2, uv_dy: wp.vec2, smp: SamplerArgs
    ) -> wp.vec4:
        """Layer ``layer`` sampled from the atlas at layer UV ``uv`` with layer-UV derivatives.

        The footprint is measured in tile texels; ``smp.max_lod`` must already hold the safe clamp.
        An anisotropic footprint's taps are placed in layer UV and each wrapped into the tile, so
        no tap reads a neighbouring tile.
        """
        fp = uv_footprint(wp.vec2(float(layout.tile_width), float(layout.tile_height)), uv_dx, uv_dy, smp)
        result = wp.vec4(0.0)
        for k in range(footprint_taps(fp)):
            result += sample(atlas, 0, tile_uv(atlas, layout, layer, footprint_uv(uv, fp, k)), fp[0], smp)
        return footprint_mean(result, fp)

    return wp.func(specialised(sample_tile, name))


sample_tile = _sample_tile(sample_lod, "sample_tile")
sample_tile_outlined = _sample_tile(sample_lod_outlined, "sample_tile_outlined")  # for the generated adjoint


@wp.func
def map_texel(n: wp.int32, u: float) -> wp.int32:
    """The texel (of ``n``) containing coordinate ``u`` (``u·n``), clamped to ``[0, n)``."""
    return wp.clamp(int(wp.floor(wp.clamp(u, -1.0, 2.0) * float(n))), 0, n - 1)


@wp.struct
class AtlasArgs:
    """What every pixel of an atlas splat reads: the atlas and its layout, the index and weight maps
    (``[h, w, k]``, read with nearest filtering, clamped, in UV0), the layers' tiling (1 or L values),
    the sampler, and whether the weights are normalised."""

    atlas: TextureView
    layout: AtlasLayout
    indices: wp.array3d(dtype=wp.int32)
    weights: wp.array3d(dtype=float)
    tiling: wp.array(dtype=float)
    smp: SamplerArgs
    normalize: wp.int32


@wp.struct
class AtlasPixels:
    """The per-pixel G-buffer arrays an atlas splat reads: UV0, its derivatives and the mask."""

    uv0: wp.array(dtype=wp.vec2)
    uv0_dx: wp.array(dtype=wp.vec2)
    uv0_dy: wp.array(dtype=wp.vec2)
    mask: wp.array(dtype=float)


def _atlas_body(sample_tile, name: str):
    def body(args: AtlasArgs, pixels: AtlasPixels, i: wp.int32, out: wp.array2d(dtype=float)):
        """``out[i]`` = ``Σ_j w_j · layer_{idx_j}(uv0[i] · tiling)`` over the ``k`` index-map entries
        of the texel containing ``uv0``. Every entry is sampled, zero weights included, so weight
        gradients are exact. With ``normalize`` the weights are clamped to ``>= 0`` and divided by their sum.
        """
        colour = wp.vec4(0.0)
        if pixels.mask[i] != 0.0:
            uv = pixels.uv0[i]
            if wp.isfinite(uv):
                # The fields read once, not per entry: each read is adjoint code to compile.
                atlas, layout, indices, weights, tiling, smp = args.atlas, args.layout, args.indices, args.weights, args.tiling, args.smp
                uv_dx, uv_dy = pixels.uv0_dx[i], pixels.uv0_dy[i]
                row = map_texel(indices.shape[0], 1.0 - uv[1])
                col = map_texel(indices.shape[1], uv[0])
                k = indices.shape[2]
                total = float(0.0)
                for j in range(MAX_ENTRIES):
                    if j < k:
                        total += wp.max(weights[row, col, j], 0.0)
                for j in range(MAX_ENTRIES):
                    if j < k:
                        w = weights[row, col, j]
                        if args.normalize != 0:
                            w = wp.max(w, 0.0) / wp.max(total, ATLAS_EPS)
                        layer = wp.clamp(indices[row, col, j], 0, layout.num_tiles - 1)
                        t = tiling[wp.min(layer, tiling.shape[0] - 1)]
                        colour += w * sample_tile(atlas, layout, layer, uv * t, uv_dx * t, uv_dy * t, smp)
            else:
                colour = wp.vec4(wp.nan)
        write_channels(out, i, colour)

    return inlined(specialised(body, name))


@family()
def atlas_kernels() -> Kernels:
    """The atlas splat's forward kernel and its generated adjoint (texels, weights, tiling and the
    G-buffer's UVs all differentiate through it)."""
    forward, _, adjoint = pixel_kernels("splat_atlas", module=MODULE, args=AtlasArgs, pixels=AtlasPixels, out=wp.array2d(dtype=float),
                                        body=_atlas_body(sample_tile, "atlas_pixel"), adjoint_body=_atlas_body(sample_tile_outlined, "atlas_pixel_outlined"))  # fmt: skip
    return Kernels(forward, None, adjoint)
