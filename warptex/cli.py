"""Command line: ``warptex [render|demo] [options]`` (also ``python -m warptex``); ``render`` is the default."""

from __future__ import annotations

import argparse
import sys


COMMANDS = ("render", "demo")


def _resolution(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 360x480 (height x width), got {text!r}") from None
    if h < 2 or w < 2:
        raise argparse.ArgumentTypeError(f"resolution must be at least 2x2, got {text!r}")
    return h, w


def _vector(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers x,y,z, got {text!r}") from None
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
    render.add_argument("--resolution", type=_resolution, default=(512, 512), help="image size HxW (default: 512x512)")
    render.add_argument("--eye", type=_vector, default=None, help="camera position x,y,z (default: framing view)")
    render.add_argument("--target", type=_vector, default=None, help="camera look-at point x,y,z (default: mesh centre)")
    render.add_argument("--fov", type=float, default=45.0, help="vertical field of view in degrees (default: 45)")
    render.add_argument("--tiling", type=float, default=None, help="texture repeats across UV0 (default: 8, or 1 for an embedded texture)")
    render.add_argument("--seed", type=int, default=0, help="terrain and procedural texture seed (default: 0)")
    render.add_argument("--device", default=None, help="Warp device, e.g. cpu or cuda:0 (default: Warp's default)")
    demo = commands.add_parser(
        "demo",
        help="render the texture-sampling demo (filters and address modes)",
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
        argv.insert(0, "render")  # the default command; its options may be given without naming it
    args = build_parser().parse_args(argv)

    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no start-up banner or compile log in CLI output
    from warptex.demo import run_demo
    from warptex.render import run_render

    try:
        if args.command == "demo":
            paths = run_demo(args.out, texture_path=args.texture, resolution=args.resolution, device=args.device)
        else:
            paths = run_render(
                args.out,
                mesh_path=args.mesh,
                texture_path=args.texture,
                resolution=args.resolution,
                eye=args.eye,
                target=args.target,
                fov_y=args.fov,
                tiling=args.tiling,
                seed=args.seed,
                device=args.device,
            )
    except (OSError, ValueError, TypeError) as err:
        print(f"warptex: error: {err}", file=sys.stderr)
        return 1
    for path in paths:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
