"""The options of the command line: argparse types (sizes, numbers, vectors, memory) and the
options of ``warptex fit``."""

from __future__ import annotations

import argparse
import math


def resolution(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 360x480 (height x width), got {text!r}") from None
    if h < 2 or w < 2:
        raise argparse.ArgumentTypeError(f"resolution must be at least 2x2, got {text!r}")
    return h, w


def count(minimum: int):
    """An argparse type: an int >= ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    return parse


def number(low: float, high: float | None):
    """An argparse type: a finite float in ``(low, high)`` (``high=None``: no upper bound)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not (math.isfinite(value) and value > low and (high is None or value < high)):
            raise argparse.ArgumentTypeError(f"must be a finite number > {low:g}" + ("" if high is None else f" and < {high:g}") + f", got {text!r}")
        return value

    return parse


def square(text: str) -> int:
    """An argparse type: a square number >= 1 (samples per pixel)."""
    value = count(1)(text)
    if math.isqrt(value) ** 2 != value:
        raise argparse.ArgumentTypeError(f"must be a square number of samples per pixel (1, 4, 9, 16, ...), got {value}")
    return value


_UNITS = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


def memory_size(text: str) -> int:
    """An argparse type: a memory size, ``512MiB``, ``1GiB``, ``2G``, ``1.5g`` (binary units; a
    plain number is bytes), at least 1 MiB."""
    import re

    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"expected a size such as 512MiB or 2GiB, got {text!r}")
    value = int(float(match.group(1)) * _UNITS[match.group(2).lower()])
    if value < 1 << 20:
        raise argparse.ArgumentTypeError(f"must be at least 1MiB, got {text!r}")
    return value


def vector(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers x,y,z, got {text!r}") from None
    if not all(math.isfinite(v) for v in (x, y, z)):
        raise argparse.ArgumentTypeError(f"expected three finite numbers x,y,z, got {text!r}")
    return x, y, z


def height_blend(text: str) -> float | None:
    if text.lower() in ("none", "0", "0.0", "off"):
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"height blend must be a number > 0 or 'none', got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"height blend must be a number > 0 or 'none', got {text!r}")
    return value


def add_fit_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``warptex fit`` and ``examples/fit_splat.py`` (see :func:`fit_arguments`)."""
    parser.add_argument("--out", default="out/fit", help="output folder (default: %(default)s)")
    parser.add_argument("--iters", type=count(1), default=240, help="Adam iterations, coarse to fine (default: %(default)s)")
    parser.add_argument("--resolution", type=resolution, default=(192, 256), help="synthetic view size HxW (default: 192x256)")
    parser.add_argument("--views", type=int, default=2, choices=(1, 2, 3), help="synthetic views: 1 three-quarter, 2 + top-down, 3 + opposite corner (default: 2)")
    parser.add_argument("--seed", type=count(0), default=0, help="terrain and layer seed, >= 0 (default: 0)")
    parser.add_argument("--tiling-error", type=float, default=0.2, help="synthetic start: tiling x (1 + this) (default: 0.2)")
    parser.add_argument("--entropy", type=float, default=1e-4, help="weight-entropy prior, 0 for none (default: 1e-4)")
    parser.add_argument("--loss", choices=("l2", "l1"), default="l2", help="image loss in linear space (default: l2)")
    parser.add_argument("--target", action="append", default=None, help="your target image (repeat for several views; needs --gbuffer each)")
    parser.add_argument("--gbuffer", action="append", default=None, help="the target's G-buffer EXR (warptex render's gbuffer.exr, or Blender passes)")
    parser.add_argument("--layers", nargs="+", default=None, help="layer images, RGBA with height in alpha (default: the terrain's four)")
    parser.add_argument("--initial-maps", nargs="+", default=None, help="splat-map images to start from (default: uniform weights)")
    parser.add_argument("--map-size", type=resolution, default=(129, 129), help="fitted splat-map size HxW (default: 129x129)")
    parser.add_argument("--map-channels", type=count(1), default=4, help="channels per splat map (default: 4)")
    parser.add_argument("--maps", type=count(1), default=None, help="number of splat maps (default: enough for the layers)")
    parser.add_argument("--tiling", type=float, default=None, help="initial tiling of your targets (default: 1/6)")
    parser.add_argument("--no-fit-tiling", dest="fit_tiling", action="store_false", help="keep the tiling fixed")
    parser.add_argument("--projection", choices=("uv", "world_xz", "triplanar"), default="triplanar", help="layer projection (default: triplanar)")
    parser.add_argument("--height-blend", type=height_blend, default=0.2, help="height-blend transition, or none (default: 0.2)")
    parser.add_argument("--sharpness", type=float, default=4.0, help="triplanar sharpness (default: 4)")
    parser.add_argument(
        "--filter", choices=("bilinear", "trilinear", "anisotropic"), default="anisotropic", help="layer texture filter (default: %(default)s)"
    )
    parser.add_argument("--report-every", type=count(0), default=20, help="print iter, stage objective, psnr every N iterations (default: 20)")
    parser.add_argument(
        "--dist-timeout", type=number(0.0, None), default=30.0, help="under torchrun: seconds a process waits for the others during the fit before failing the run (default: 30)"
    )
    parser.add_argument("--memory", type=memory_size, default=None, help="memory for the work on one band of a view, e.g. 512MiB; larger views are fitted band by band (default: 256MiB)")
    parser.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0; under torchrun cuda is cuda:LOCAL_RANK (default: Warp's default)")


def check_fit_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """The checks of ``warptex fit`` options that involve several of them: ``parser.error`` (exit 2)."""
    if (args.target is None) != (args.gbuffer is None) or len(args.target or []) != len(args.gbuffer or []):
        parser.error(f"--target and --gbuffer go together, one G-buffer per target image; got {len(args.target or [])} --target and {len(args.gbuffer or [])} --gbuffer")


def fit_arguments(args: argparse.Namespace) -> dict:
    """The keyword arguments of :func:`warptex.apps.fit_demo.run_fit` from parsed :func:`add_fit_arguments` options
    (checked by :func:`check_fit_options`)."""
    return {
        "iters": args.iters,
        "resolution": args.resolution,
        "views": args.views,
        "seed": args.seed,
        "tiling_error": args.tiling_error,
        "entropy": args.entropy,
        "loss": args.loss,
        "targets": args.target,
        "gbuffers": args.gbuffer,
        "layers": args.layers,
        "initial_maps": args.initial_maps,
        "map_size": args.map_size,
        "map_channels": args.map_channels,
        "num_maps": args.maps,
        "tiling": args.tiling,
        "fit_tiling": args.fit_tiling,
        "projection": args.projection,
        "height_blend": args.height_blend,
        "sharpness": args.sharpness,
        "filter": args.filter,
        "report_every": args.report_every,
        "dist_timeout": args.dist_timeout,
        "memory": args.memory,
        "device": args.device,
    }
