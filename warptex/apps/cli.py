"""Command line: ``warptex [render|demo|fit|bake|assets] [options]`` (also ``python -m warptex``); ``render`` is the default."""

from __future__ import annotations

import argparse
import math
import sys


COMMANDS = ("render", "demo", "fit", "bake", "assets")


def _resolution(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 360x480 (height x width), got {text!r}") from None
    if h < 2 or w < 2:
        raise argparse.ArgumentTypeError(f"resolution must be at least 2x2, got {text!r}")
    return h, w


def _count(minimum: int):
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


def _number(low: float, high: float | None):
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


def _square(text: str) -> int:
    """An argparse type: a square number >= 1 (samples per pixel)."""
    value = _count(1)(text)
    if math.isqrt(value) ** 2 != value:
        raise argparse.ArgumentTypeError(f"must be a square number of samples per pixel (1, 4, 9, 16, ...), got {value}")
    return value


def _vector(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers x,y,z, got {text!r}") from None
    if not all(math.isfinite(v) for v in (x, y, z)):
        raise argparse.ArgumentTypeError(f"expected three finite numbers x,y,z, got {text!r}")
    return x, y, z


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="warptex", description="Differentiable texture sampling with NVIDIA Warp.")
    commands = parser.add_subparsers(dest="command")
    render = commands.add_parser(
        "render",
        help="render the default terrain, or your mesh (the default command)",
        description="Rasterise a mesh into a G-buffer, texture and light it; writes render.png, albedo.png, "
        "normals.png, render.exr (linear RGBA) and gbuffer.exr into the output folder.",
    )
    render.add_argument("--out", default="out", help="output folder (default: %(default)s)")
    render.add_argument("--mesh", default=None, help="mesh file: OBJ, PLY, STL, GLB/GLTF... (default: procedural terrain)")
    render.add_argument("--texture", default=None, help="texture image (default: the mesh's own, else procedural ground)")
    render.add_argument("--texture-layer", default=None, metavar="NAME", help="the layer of an EXR texture to read, e.g. diffuse for diffuse.R, diffuse.G... (default: its only or unprefixed layer)")
    render.add_argument("--resolution", type=_resolution, default=(512, 512), help="image size HxW (default: 512x512)")
    render.add_argument("--eye", type=_vector, default=None, help="camera position x,y,z (default: framing view)")
    render.add_argument("--target", type=_vector, default=None, help="camera look-at point x,y,z (default: mesh centre)")
    render.add_argument("--up", type=_vector, default=None, help="world direction shown upward x,y,z (default: 0,1,0; 0,0,-1 when looking straight down)")
    render.add_argument("--fov", type=_number(0.0, 180.0), default=45.0, help="vertical field of view in degrees (default: 45)")
    render.add_argument(
        "--tiling",
        type=_number(0.0, None),
        default=None,
        help="how often the texture repeats; its unit depends on the mesh. Default terrain: layer repeats per world unit "
        "(default 1/6, one repeat per 6 units). A mesh with UVs: repeats across UV0 (default 1 with the mesh's own "
        "texture, else 8). A mesh without UVs (mapped triplanar): repeats across the mesh's largest extent (default 8)",
    )
    render.add_argument("--seed", type=int, default=0, help="terrain and procedural texture seed (default: 0)")
    render.add_argument("--samples", type=_square, default=4, help="stratified samples per pixel, 1, 4, 9, 16... (anti-aliasing; default: 4)")
    render.add_argument(
        "--filter", choices=("nearest", "bilinear", "trilinear", "anisotropic"), default="anisotropic", help="texture filter (default: %(default)s)"
    )
    render.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0 (default: Warp's default)")
    demo = commands.add_parser(
        "demo",
        help="render the texture-sampling demo (filters and address modes)",
        description="Sample a texture on a ground plane (nearest, bilinear, trilinear, anisotropic) and show the "
        "address modes; writes demo.png, demo_trilinear.exr and demo_anisotropic.exr into the output folder.",
    )
    demo.add_argument("--out", default="out", help="output folder (default: %(default)s)")
    demo.add_argument("--texture", default=None, help="image file to use (default: a procedural checkerboard)")
    demo.add_argument("--resolution", type=_resolution, default=(360, 480), help="panel size HxW (default: 360x480)")
    demo.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0 (default: Warp's default)")
    fit = commands.add_parser(
        "fit",
        help="fit splat maps and tiling to images (the default terrain, or your targets)",
        description="Recover splat maps and tiling from images by gradient descent. Without --target: the "
        "default terrain rendered with true splat maps and tiling is the target, the fit starts from uniform "
        "weights and a tiling 20% off. Under torchrun (torchrun --nproc-per-node N -m warptex fit) the views are split "
        "over the N processes. Writes target.png, initial.png, fitted.png, comparison.png, "
        "splat_true.png, splat_fitted.png, splat_maps.png, splat_fitted.exr, curve.png and summary.json.",
    )
    add_fit_arguments(fit)
    bake = commands.add_parser(
        "bake",
        help="bake a mesh's texturing into a UV atlas and export a glTF asset (.glb)",
        description="Texture a mesh as render does (or with the technique named), bake it into the mesh's UV atlas "
        "(its own UVs when usable, else an automatic atlas from xatlas) and write OUT (.glb) with OUT_color.png "
        "(and OUT_normal.png with --normal-map, OUT_alpha.png for layers with height in alpha) beside it.",
    )
    bake.add_argument("--out", default="out/asset.glb", help="the .glb file to write (default: %(default)s)")
    bake.add_argument("--mesh", default=None, help="mesh file: OBJ, PLY, STL, GLB/GLTF... (default: procedural terrain)")
    bake.add_argument("--technique", choices=("triplanar", "biplanar", "splat"), default=None, help="texturing (default: splat for the terrain or with --layers, else triplanar)")
    bake.add_argument("--texture", default=None, help="texture image for triplanar/biplanar (default: procedural ground)")
    bake.add_argument("--normal-map", default=None, help="tangent-space normal map (OpenGL style), mapped like the texture and baked too")
    bake.add_argument("--layers", nargs="+", default=None, help="splat layer images (RGBA, height in alpha), with --splat")
    bake.add_argument("--splat", default=None, help="RGBA splat map in the mesh's UV0 weighing --layers (4 per map)")
    bake.add_argument("--stochastic", choices=("hash4", "cheap2", "hex"), default=None, help="anti-tiling for the texture or layers (default: none)")
    bake.add_argument("--size", type=_count(2), default=2048, help="atlas texels per side (default: %(default)s)")
    bake.add_argument("--padding", type=_count(0), default=None, help="texels between the atlas's charts (default: twice the gutter)")
    bake.add_argument("--gutter", type=_count(0), default=None, help="texels filled around each chart (default: enough for the mips of a 512-pixel view)")
    bake.add_argument("--tiling", type=_number(0.0, None), default=None, help="texture repeats across the mesh (default: 8; layers: 1/6 per unit)")
    bake.add_argument("--seed", type=int, default=0, help="terrain and procedural texture seed (default: 0)")
    bake.add_argument(
        "--filter", choices=("nearest", "bilinear", "trilinear", "anisotropic"), default="anisotropic", help="texture filter (default: %(default)s)"
    )
    bake.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0 (default: Warp's default)")
    assets = commands.add_parser(
        "assets",
        help="write the sample inputs the README's snippets read (the terrain's layers and splat map)",
        description="Write grass.png, gravel.png, rock.png and snow.png (RGBA: colour, height in alpha) and "
        "splat.png (their weights) of the default terrain into the output folder.",
    )
    assets.add_argument("--out", default="assets", help="output folder (default: %(default)s)")
    assets.add_argument("--seed", type=int, default=0, help="terrain and layer seed (default: 0)")
    assets.add_argument("--device", default=None, help=argparse.SUPPRESS)
    parser.commands = {"render": render, "demo": demo, "fit": fit, "bake": bake, "assets": assets}  # for errors in a command's own usage
    return parser


def _height_blend(text: str) -> float | None:
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
    parser.add_argument("--iters", type=_count(1), default=240, help="Adam iterations, coarse to fine (default: %(default)s)")
    parser.add_argument("--resolution", type=_resolution, default=(192, 256), help="synthetic view size HxW (default: 192x256)")
    parser.add_argument("--views", type=int, default=2, choices=(1, 2, 3), help="synthetic views: 1 three-quarter, 2 + top-down, 3 + opposite corner (default: 2)")
    parser.add_argument("--seed", type=_count(0), default=0, help="terrain and layer seed, >= 0 (default: 0)")
    parser.add_argument("--tiling-error", type=float, default=0.2, help="synthetic start: tiling x (1 + this) (default: 0.2)")
    parser.add_argument("--entropy", type=float, default=1e-4, help="weight-entropy prior, 0 for none (default: 1e-4)")
    parser.add_argument("--loss", choices=("l2", "l1"), default="l2", help="image loss in linear space (default: l2)")
    parser.add_argument("--target", action="append", default=None, help="your target image (repeat for several views; needs --gbuffer each)")
    parser.add_argument("--gbuffer", action="append", default=None, help="the target's G-buffer EXR (warptex render's gbuffer.exr, or Blender passes)")
    parser.add_argument("--layers", nargs="+", default=None, help="layer images, RGBA with height in alpha (default: the terrain's four)")
    parser.add_argument("--initial-maps", nargs="+", default=None, help="splat-map images to start from (default: uniform weights)")
    parser.add_argument("--map-size", type=_resolution, default=(129, 129), help="fitted splat-map size HxW (default: 129x129)")
    parser.add_argument("--map-channels", type=_count(1), default=4, help="channels per splat map (default: 4)")
    parser.add_argument("--maps", type=_count(1), default=None, help="number of splat maps (default: enough for the layers)")
    parser.add_argument("--tiling", type=float, default=None, help="initial tiling of your targets (default: 1/6)")
    parser.add_argument("--no-fit-tiling", dest="fit_tiling", action="store_false", help="keep the tiling fixed")
    parser.add_argument("--projection", choices=("uv", "world_xz", "triplanar"), default="triplanar", help="layer projection (default: triplanar)")
    parser.add_argument("--height-blend", type=_height_blend, default=0.2, help="height-blend transition, or none (default: 0.2)")
    parser.add_argument("--sharpness", type=float, default=4.0, help="triplanar sharpness (default: 4)")
    parser.add_argument(
        "--filter", choices=("bilinear", "trilinear", "anisotropic"), default="anisotropic", help="layer texture filter (default: %(default)s)"
    )
    parser.add_argument("--report-every", type=_count(0), default=20, help="print iter, stage objective, psnr every N iterations (default: 20)")
    parser.add_argument(
        "--dist-timeout", type=_number(0.0, None), default=30.0, help="under torchrun: seconds a process waits for the others during the fit before failing the run (default: 30)"
    )
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
        "device": args.device,
    }


def fit_report(summary: dict) -> str:
    """The result lines printed after a fit."""
    processes = f" on {summary['world_size']} processes" if summary.get("world_size", 1) > 1 else ""
    lines = [f"fit: {summary['iterations']} iterations{processes} in {summary['fit_seconds']:.1f} s; PSNR {summary['initial_psnr_db']:.2f} -> {summary['final_psnr_db']:.2f} dB"]
    tiling = ", ".join(f"{t:.6f}" for t in summary["fitted_tiling"])
    if summary["mode"] == "synthetic":
        lines.append(f"fit: tiling {tiling} (true {summary['true_tiling']:.6f}, error {summary['tiling_error_percent']:.3f}%)")
        lines.append(f"fit: splat weights MAE {summary['splat_mae_covered']:.4f} on {summary['covered_texels']} covered texels (uniform start: {summary['splat_mae_uniform_start']:.4f})")
    else:
        lines.append(f"fit: tiling {tiling}")
    return "\n".join(lines)


def version() -> str:
    """``warptex X.Y.Z (warp-lang A.B.C, Python D.E.F)``, without importing Warp."""
    from importlib import metadata

    try:
        ours = metadata.version("warptex")
    except metadata.PackageNotFoundError:  # a checkout that is not installed
        import re
        from pathlib import Path

        match = re.search(r'^version = "([^"]+)"', (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text(), re.M)
        ours = match.group(1) if match else "unknown"
    try:
        warp = metadata.version("warp-lang")
    except metadata.PackageNotFoundError:
        warp = "not installed"
    return f"warptex {ours} (warp-lang {warp}, Python {sys.version.split()[0]})"


def main(argv: list[str] | None = None) -> int:
    """Run the command line; the exit status: 0, 1 on an error (one line on stderr, no files
    written), 2 on bad options (argparse), 130 on Ctrl-C."""
    argv = _joined_vectors(list(sys.argv[1:] if argv is None else argv))
    if not argv or argv[0] not in COMMANDS + ("-h", "--help", "--version"):
        argv.insert(0, "render")  # the default command; its options may be given without naming it
    parser = build_parser()
    parser.add_argument("--version", action="version", version=version())
    args = parser.parse_args(argv)
    if args.command == "fit":
        check_fit_options(parser.commands["fit"], args)
    try:
        paths = _run(args)
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM under torchrun (apps.distributed.Terminated)
        print(f"warptex: {str(err) or 'interrupted'}; no files were written", file=sys.stderr)
        return getattr(err, "status", 130)
    except (OSError, ValueError, TypeError, MemoryError) as err:
        print(f"warptex: error: {_one_line(err)}", file=sys.stderr)
        return 1
    except RuntimeError as err:
        from warptex.fit.distributed import DistributedError

        if isinstance(err, DistributedError):  # another process of a torchrun job failed
            print(f"warptex: error: {_one_line(err)}", file=sys.stderr)
            return 1
        if "alloc" not in str(err).lower():  # Warp reports a failed allocation so; anything else is a bug
            raise
        print(f"warptex: error: out of memory: {_one_line(err)}", file=sys.stderr)
        return 1
    for path in paths:
        print(f"wrote {path}")
    return 0


VECTOR_OPTIONS = ("--eye", "--target", "--up")


def _joined_vectors(argv: list[str]) -> list[str]:
    """``--eye -30,25,40`` as ``--eye=-30,25,40``: argparse takes a value that starts with ``-``
    and is not one plain number for an option, and would report "expected one argument"."""
    out = []
    for word in argv:
        if out and out[-1] in VECTOR_OPTIONS and word[:1] == "-" and (word[1:2].isdigit() or word[1:2] == "."):
            out[-1] = f"{out[-1]}={word}"
        else:
            out.append(word)
    return out


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())  # a message spread over lines (OpenEXR's, NumPy's) on one
    return text or ("out of memory" if isinstance(err, MemoryError) else type(err).__name__)


def _run(args: argparse.Namespace) -> list:
    from warptex._warp import init_quietly

    init_quietly()  # no start-up banner or compile log, no "no CUDA driver" warning on a CPU machine
    if args.device is not None:
        from warptex._validate import checked_device

        checked_device("--device", args.device)  # before any work: which devices there are
    if args.command == "fit":
        return _fit(args)
    if args.command == "bake":
        from warptex.apps.bake import run_bake

        paths = {"mesh_path": args.mesh, "texture_path": args.texture, "layer_paths": args.layers, "splat_path": args.splat, "normal_map_path": args.normal_map}
        options = {k: getattr(args, k) for k in ("technique", "stochastic", "size", "padding", "gutter", "tiling", "seed", "filter", "device")}
        return run_bake(args.out, **paths, **options)
    if args.command == "assets":
        from warptex.apps.assets import run_assets

        return run_assets(args.out, seed=args.seed)
    if args.command == "demo":
        from warptex.apps.demo import run_demo

        return run_demo(args.out, texture_path=args.texture, resolution=args.resolution, device=args.device)
    from warptex.apps.render import run_render

    return run_render(
        args.out,
        mesh_path=args.mesh,
        texture_path=args.texture,
        texture_layer=args.texture_layer,
        resolution=args.resolution,
        eye=args.eye,
        target=args.target,
        up=args.up,
        fov_y=args.fov,
        tiling=args.tiling,
        seed=args.seed,
        samples=args.samples,
        filter=args.filter,
        device=args.device,
    )


def _fit(args: argparse.Namespace) -> list:
    """``warptex fit``, in one process or as a rank of a torchrun job (:mod:`warptex.apps.distributed`)."""
    from warptex.apps.distributed import from_environment
    from warptex.apps.fit_demo import run_fit

    kwargs = fit_arguments(args)
    job = from_environment()
    if job is None:
        summary = run_fit(args.out, **kwargs)
    else:
        try:
            kwargs["device"] = job.device(args.device)
            job.start(kwargs["device"])
            summary = run_fit(args.out, job=job, **kwargs)
            job.finish()
        finally:
            job.close()
    if summary["files"]:
        print(fit_report(summary))
    return summary["files"]


if __name__ == "__main__":
    sys.exit(main())
