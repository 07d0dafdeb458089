"""Command line: ``warptex [demo] [options]`` (also ``python -m warptex``)."""

from __future__ import annotations

import argparse
import sys


COMMANDS = ("demo",)


def _resolution(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 360x480 (height x width), got {text!r}") from None
    if h < 2 or w < 2:
        raise argparse.ArgumentTypeError(f"resolution must be at least 2x2, got {text!r}")
    return h, w


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="warptex", description="Differentiable texture sampling with NVIDIA Warp.")
    commands = parser.add_subparsers(dest="command")
    demo = commands.add_parser(
        "demo",
        help="render the texture-sampling demo (the default command)",
        description="Sample a texture on a ground plane (nearest, bilinear, trilinear) and show the address "
        "modes; writes demo.png and demo_trilinear.exr into the output folder.",
    )
    demo.add_argument("--out", default="out", help="output folder (default: %(default)s)")
    demo.add_argument("--texture", default=None, help="image file to use (default: a procedural checkerboard)")
    demo.add_argument("--resolution", type=_resolution, default=(360, 480), help="panel size HxW (default: 360x480)")
    demo.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0 (default: Warp's default)")
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in COMMANDS + ("-h", "--help"):
        argv.insert(0, "demo")  # the default command; its options may be given without naming it
    args = build_parser().parse_args(argv)

    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no start-up banner or compile log in CLI output
    from warptex.demo import run_demo

    try:
        paths = run_demo(args.out, texture_path=args.texture, resolution=args.resolution, device=args.device)
    except (OSError, ValueError, TypeError) as err:
        print(f"warptex: error: {err}", file=sys.stderr)
        return 1
    for path in paths:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
