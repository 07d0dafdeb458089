"""Command line: ``warptex [render|demo|fit|bake|assets] [options]`` (also ``python -m warptex``); ``render`` is the default."""

from __future__ import annotations

import argparse
import difflib
import os
import sys
import warnings

from warptex.apps import collector
from warptex.apps.arguments import add_fit_arguments, check_fit_options, count, fit_arguments, memory_size, number, resolution, square, vector


COMMANDS = ("render", "demo", "fit", "bake", "assets")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="warptex", description="Differentiable texture sampling with NVIDIA Warp.")
    commands = parser.add_subparsers(dest="command")
    render = _command(commands, "render", out=("out", "output folder (default: %(default)s)"), help="render the default terrain, or your mesh (the default command)",
        description="Rasterise a mesh into a G-buffer, texture and light it; writes render.png, albedo.png, "
        "normals.png, render.exr (linear RGBA) and gbuffer.exr into the output folder.")  # fmt: skip
    render.add_argument("--mesh", default=None, help="mesh file: OBJ, PLY, STL, GLB/GLTF... (default: procedural terrain)")
    render.add_argument("--texture", default=None, help="texture image (default: the mesh's own, else procedural ground)")
    render.add_argument("--texture-layer", default=None, metavar="NAME", help="the layer of an EXR texture to read, e.g. diffuse for diffuse.R, diffuse.G... (default: its only or unprefixed layer)")
    render.add_argument("--resolution", type=resolution, default=(512, 512), help="image size HxW (default: 512x512)")
    render.add_argument("--eye", type=vector, default=None, help="camera position x,y,z (default: framing view)")
    render.add_argument("--target", type=vector, default=None, help="camera look-at point x,y,z (default: mesh centre)")
    render.add_argument("--up", type=vector, default=None, help="world direction shown upward x,y,z (default: 0,1,0; 0,0,-1 when looking straight down)")
    render.add_argument("--fov", type=number(0.0, 180.0), default=45.0, help="vertical field of view in degrees (default: 45)")
    render.add_argument(
        "--tiling",
        type=number(0.0, None),
        default=None,
        help="how often the texture repeats; its unit depends on the mesh. Default terrain: layer repeats per world unit "
        "(default 1/6, one repeat per 6 units). A mesh with UVs: repeats across UV0 (default 1 with the mesh's own "
        "texture, else 8). A mesh without UVs (mapped triplanar): repeats across the mesh's largest extent (default 8)",
    )
    render.add_argument("--seed", type=int, default=0, help="terrain and procedural texture seed (default: 0)")
    render.add_argument("--samples", type=square, default=4, help="stratified samples per pixel, 1, 4, 9, 16... (anti-aliasing; default: 4)")
    _add_filter(render)
    _add_memory(render, "the image", "larger images are made band by band")
    render.add_argument("--technique", choices=("uv", "triplanar", "biplanar", "splat"), default=None,
                        help="texturing of a mesh: through its UVs (uv) or projected (default: uv where it has UVs, else triplanar), as bake bakes it; the terrain is splat-blended")
    _add_device(render)
    _add_quiet(render)
    demo = _command(commands, "demo", out=("out", "output folder (default: %(default)s)"), help="render the texture-sampling demo (filters and address modes)",
        description="Sample a texture on a ground plane (nearest, bilinear, trilinear, anisotropic) and show the "
        "address modes; writes demo.png, demo_trilinear.exr and demo_anisotropic.exr into the output folder.")  # fmt: skip
    demo.add_argument("--texture", default=None, help="image file to use (default: a procedural checkerboard)")
    demo.add_argument("--resolution", type=resolution, default=(360, 480), help="panel size HxW (default: 360x480)")
    _add_device(demo)
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
    _add_quiet(fit)
    bake = _command(commands, "bake", out=("out/asset.glb", "the .glb file to write (default: %(default)s)"), help="bake a mesh's texturing into a UV atlas and export a glTF asset (.glb)",
        description="Texture a mesh as render does (or with the technique named), bake it into the mesh's UV atlas "
        "(its own UVs when usable, else an automatic atlas from xatlas) and write OUT (.glb) with OUT_color.png "
        "(and OUT_normal.png with --normal-map, OUT_alpha.png for layers with height in alpha) beside it.")  # fmt: skip
    bake.add_argument("--mesh", default=None, help="mesh file: OBJ, PLY, STL, GLB/GLTF... (default: procedural terrain)")
    bake.add_argument("--technique", choices=("uv", "triplanar", "biplanar", "splat"), default=None,
                      help="texturing, as render's: through the mesh's UVs (uv) or projected (default: splat for the terrain or with --layers; triplanar with --normal-map; else uv where the mesh has UVs, triplanar where not)")
    bake.add_argument("--texture", default=None, help="texture image (default: the mesh's own, else a procedural ground)")
    bake.add_argument("--normal-map", default=None, help="tangent-space normal map (OpenGL style), mapped like the texture and baked too")
    bake.add_argument("--layers", nargs="+", default=None, help="splat layer images (RGBA, height in alpha), with --splat")
    bake.add_argument("--splat", default=None, help="RGBA splat map in the mesh's UV0 weighing --layers (4 per map)")
    bake.add_argument("--stochastic", choices=("hash4", "cheap2", "hex"), default=None, help="anti-tiling for the texture or layers (default: none)")
    bake.add_argument("--size", type=count(2), default=2048, help="atlas texels per side (default: %(default)s)")
    bake.add_argument("--padding", type=count(0), default=None, help="texels between the atlas's charts (default: the gutter)")
    bake.add_argument("--gutter", type=count(0), default=None, help="texels filled around each chart (default: enough for the mips of a 512-pixel view)")
    bake.add_argument("--tiling", type=number(0.0, None), default=None, help="texture repeats, as for render: across UV0 (default 1 with the mesh's own texture, else 8) or across the mesh projected (default 8); layers: per unit (default 1/6)")
    bake.add_argument("--seed", type=int, default=0, help="terrain and procedural texture seed (default: 0)")
    _add_filter(bake)
    bake.add_argument(
        "--atlas", choices=("auto", "xatlas", "projection"), default="auto",
        help="how a mesh without usable UVs is unwrapped: xatlas (few seams), projection (charts along six axes, for large scans), or auto: xatlas up to 50,000 faces (default: auto)",
    )
    bake.add_argument("--keep-uvs", action="store_true", help="bake into the mesh's own UVs even where charts overlap (they then share texels) or parts have none; without it such UVs are replaced by an atlas, with a warning saying why")
    _add_memory(bake, "the atlas", "larger atlases are baked band by band")
    _add_device(bake)
    _add_quiet(bake)
    assets = _command(commands, "assets", out=("assets", "output folder (default: %(default)s)"), help="write the sample inputs the docs' snippets read (the terrain's layers and splat map)",
        description="Write grass.png, gravel.png, rock.png and snow.png (RGBA: colour, height in alpha) and "
        "splat.png (their weights) of the default terrain into the output folder.")  # fmt: skip
    assets.add_argument("--seed", type=int, default=0, help="terrain and layer seed (default: 0)")
    assets.add_argument("--device", default=None, help=argparse.SUPPRESS)
    parser.commands = {"render": render, "demo": demo, "fit": fit, "bake": bake, "assets": assets}  # for errors in a command's own usage
    return parser


def _command(commands, name: str, *, help: str, description: str, out: tuple[str, str]) -> argparse.ArgumentParser:  # noqa: A002 (argparse's word)
    """A command's parser, with its ``--out`` (``(default, help)``) first."""
    command = commands.add_parser(name, help=help, description=description)
    command.add_argument("--out", default=out[0], help=out[1])
    return command


def _add_quiet(command: argparse.ArgumentParser) -> None:
    command.add_argument("--quiet", "-q", action="store_true", help="no progress bar (there is none either when stderr is not a terminal)")


def _progress(args: argparse.Namespace) -> bool | None:
    """A command's progress bar: off with --quiet, else on a terminal only (tqdm decides)."""
    return False if args.quiet else None


def _reporter(command: str):
    """How a command prints the line saying what it used: on stdout, above its progress bar."""

    def report(line: str) -> None:
        from tqdm import tqdm

        tqdm.write(f"{command}: {line}", file=sys.stdout)

    return report


def _add_filter(command: argparse.ArgumentParser) -> None:
    command.add_argument("--filter", choices=("nearest", "bilinear", "trilinear", "anisotropic"), default="anisotropic", help="texture filter (default: %(default)s)")


def _add_memory(command: argparse.ArgumentParser, band_of: str, larger: str) -> None:
    command.add_argument("--memory", type=memory_size, default=None, help=f"memory for the work on one band of {band_of}, e.g. 512MiB or 2GiB; {larger} (default: 256MiB)")


def _add_device(command: argparse.ArgumentParser) -> None:
    command.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0 (default: Warp's default)")


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


def main(argv: list[str] | None = None, *, process: bool = False) -> int:
    """Run the command line; the exit status: 0, 1 on an error (one line on stderr, no files
    written), 2 on bad options (argparse), 130 on Ctrl-C. ``process``: this is the process's
    entry (:func:`entry`): once the files are written and named, a Ctrl-C ends the process at once
    with status 0, set while Ctrl-C is still ignored so that no moment is left in which it would
    raise into a run that is over."""
    argv = _joined_vectors(list(sys.argv[1:] if argv is None else argv))
    parser = build_parser()
    if argv and not argv[0].startswith("-") and argv[0] not in COMMANDS:  # no command takes a positional argument
        close = difflib.get_close_matches(argv[0], COMMANDS, n=1)
        parser.error(f"unknown command {argv[0]!r}{f'; did you mean {close[0]!r}?' if close else ''} (commands: {', '.join(COMMANDS)})")
    if not argv or argv[0] not in COMMANDS + ("-h", "--help", "--version"):
        argv.insert(0, "render")  # the default command; its options may be given without naming it
    parser.add_argument("--version", action="version", version=version())
    args = parser.parse_args(argv)
    if args.command == "fit":
        check_fit_options(parser.commands["fit"], args)
    written = None  # output sets moved into place before the run (Ctrl-C may come after the job's own)
    try:
        from warptex._interrupts import interrupts_deferred, interrupts_ignored

        # The libraries' imports finish before a Ctrl-C is raised: one cut inside would leave a
        # module half made, and trimesh catches BaseException around its optional imports, so it
        # would swallow the KeyboardInterrupt and fail later with another error.
        with interrupts_deferred():
            import trimesh  # noqa: F401
            from tqdm import tqdm

            from warptex import _output

            # tqdm makes its write lock on first use, importing multiprocessing with its thread lock
            # held: a Ctrl-C there (the first progress bar, or the line saying what a job uses)
            # left tqdm without a lock, and the run ended with its AttributeError, not the one line.
            tqdm.get_lock()
        written = _output.commits()
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            paths = _run(args)
        with interrupts_ignored():  # the files are written: a Ctrl-C while their names print comes after the run
            for path in paths:
                print(f"wrote {path}")
            if process:
                _exit_on_interrupt(0)
    except BaseException as err:
        status = _reported(err, written)
        if status is None:
            raise
        return status
    return 0


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning (a mesh's missing material...) as one line of the command's own, not Python's
    ``file:line: UserWarning:`` with the source line."""
    print(f"warptex: warning: {message}", file=sys.stderr)


def _reported(err: BaseException, written) -> int | None:
    """Say on stderr, in one line, why the run ended; its exit status, or None for an error that
    is a bug (its traceback is then the report). A signal that arrives while saying so (torchrun
    sends SIGTERM to every rank once one fails) does not replace the line."""
    from warptex._interrupts import interrupts_ignored

    while True:
        try:
            with interrupts_ignored():
                return _report(err, written)
        except KeyboardInterrupt:  # came before the block dropped it: say the first thing again
            continue


def _report(err: BaseException, written) -> int | None:
    if isinstance(err, KeyboardInterrupt):  # Ctrl-C, or SIGTERM under torchrun (apps.distributed.Terminated)
        from warptex import _output

        what = "no files were written" if written is None or _output.commits() == written else "its files were written before it"
        print(f"warptex: {str(err) or 'interrupted'}; {what}", file=sys.stderr)
        return getattr(err, "status", 130)
    if isinstance(err, (OSError, ValueError, TypeError, MemoryError)):
        print(f"warptex: error: {_one_line(err)}", file=sys.stderr)
        return 1
    if isinstance(err, RuntimeError):
        from warptex.fit.distributed import DistributedError

        if isinstance(err, DistributedError):  # another process of a torchrun job failed
            print(f"warptex: error: {_one_line(err)}", file=sys.stderr)
            return 1
        if "alloc" in str(err).lower():  # Warp reports a failed allocation so; anything else is a bug
            print(f"warptex: error: out of memory: {_one_line(err)}", file=sys.stderr)
            return 1
    return None


def entry() -> None:
    """The ``warptex`` command and ``python -m warptex``: :func:`main`, then exit with its status.
    After a Ctrl-C the process ends at once (its files are already as they were, its message is
    out), without Python's shutdown, which would first wait for any kernel compile still running
    on another thread. Once the run is over, a Ctrl-C in that wait ends the process at once with
    the run's status, and one in the rest of the shutdown (tenths of a second, mostly the
    compiler's own clean-up after Python's) is ignored: the run is done, and the signal would
    otherwise end it with a failing status."""
    import atexit
    import signal

    collector.pause()  # through the imports: collector.resume() before the job
    status = main(process=True)
    sys.stdout.flush()
    sys.stderr.flush()
    if status == 130:
        os._exit(status)
    _exit_on_interrupt(status)
    atexit.register(signal.signal, signal.SIGINT, signal.SIG_IGN)  # runs after other threads are joined
    sys.exit(status)


def _exit_on_interrupt(status: int) -> None:
    """From now on a Ctrl-C ends the process at once with ``status`` (the run is over)."""
    import signal

    sys.stdout.flush()
    signal.signal(signal.SIGINT, lambda number, frame: os._exit(status))


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
        options = {k: getattr(args, k) for k in ("technique", "stochastic", "size", "padding", "gutter", "tiling", "seed", "filter", "atlas", "keep_uvs", "memory", "device")}
        collector.resume()
        return run_bake(args.out, **paths, **options, progress=_progress(args), report=_reporter("bake"))
    if args.command == "assets":
        from warptex.apps.assets import run_assets

        collector.resume()
        return run_assets(args.out, seed=args.seed)
    if args.command == "demo":
        from warptex.apps.demo import run_demo

        collector.resume()
        return run_demo(args.out, texture_path=args.texture, resolution=args.resolution, device=args.device)
    from warptex.apps.render import run_render

    collector.resume()
    return run_render(
        args.out,
        mesh_path=args.mesh,
        texture_path=args.texture,
        texture_layer=args.texture_layer,
        technique=args.technique,
        resolution=args.resolution,
        eye=args.eye,
        target=args.target,
        up=args.up,
        fov_y=args.fov,
        tiling=args.tiling,
        seed=args.seed,
        samples=args.samples,
        filter=args.filter,
        memory=args.memory,
        device=args.device,
        progress=_progress(args),
        report=_reporter("render"),
    )


def _fit(args: argparse.Namespace) -> list:
    """``warptex fit``, in one process or as a rank of a torchrun job (:mod:`warptex.apps.distributed`)."""
    from warptex.apps.distributed import from_environment
    from warptex.apps.fit_demo import run_fit

    kwargs = {**fit_arguments(args), "progress": _progress(args)}
    collector.resume()
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
