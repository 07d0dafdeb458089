"""Time G-buffer rasterisation of a mesh (default: the 16k-face bunny at 512 x 512).

Seeded and repeatable: a warm-up run (BVH build + kernel compile), then timed repeats, minimum
reported. The BVH build is included in each timed run, as a user calling ``rasterize`` pays it.
As a peer, the same primary rays are cast with trimesh's ray module when it is usable here.

    python benchmarks/bench_gbuffer.py [--mesh ../shared/data/meshes/bunny.ply] [--resolution 512]
"""

import argparse
import time
from pathlib import Path

import numpy as np
import warp as wp

from warptex.camera import look_at
from warptex.gbuffer import load_mesh
from warptex.raster import rasterize

DEFAULT_MESH = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes" / "bunny.ply"


def best_of(fn, repeats):
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default=str(DEFAULT_MESH))
    parser.add_argument("--resolution", type=int, default=512)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default=None)
    args = parser.parse_args(argv)
    wp.config.log_level = wp.LOG_WARNING

    mesh = load_mesh(args.mesh)
    centre, radius = mesh.bounds.mean(axis=0), np.linalg.norm(mesh.extents)
    camera = look_at(centre + np.array([0.3, 0.4, 1.0]) * radius * 1.2, centre, fov_y=40.0, resolution=(args.resolution,) * 2)

    def run():
        g = rasterize(mesh, camera, device=args.device)
        wp.synchronize_device(g.device)
        return g

    seconds = best_of(run, args.repeats)
    pixels = args.resolution**2
    coverage = run().mask.numpy().mean()
    print(f"{Path(args.mesh).name}: {len(mesh.faces):,} faces, {args.resolution}x{args.resolution}, coverage {coverage:.1%}")
    print(f"warptex rasterize: {seconds * 1e3:.1f} ms  ({pixels / seconds / 1e6:.2f} Mpixels/s, BVH build included)")

    try:  # peer: trimesh's ray casting (pure NumPy without embree), on a subset to keep it short
        origins, directions = camera.rays()
        sub = slice(None, None, 16)
        o, d = origins.reshape(-1, 3)[sub], directions.reshape(-1, 3)[sub]
        intersector = mesh.ray
        peer = best_of(lambda: intersector.intersects_first(o, d), 1) * 16
        print(f"trimesh ray.intersects_first ({type(intersector).__name__}), scaled to all pixels: {peer * 1e3:.0f} ms "
              f"-> warptex is {peer / seconds:.1f}x faster")
    except Exception as err:  # noqa: BLE001 (the peer is optional)
        print(f"trimesh ray peer skipped: {type(err).__name__}: {err}")


if __name__ == "__main__":
    main()
