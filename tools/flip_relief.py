"""How much of a target's surface its 180° flip about a body axis moves: is the flip observable?

    python -m spacepose.tools.flip_relief --target tdrs --axis z [--samples 20000] [--json OUT]

Area-uniform surface samples are turned half round about ``axis`` through the bundle centre (the
turn of :func:`spacepose.flip.flipped_pose`); each turned sample's distance to the nearest sample of
the unturned surface is how far the flip moves that bit of surface out of where the target was.
Printed: the share of the surface moved by more than 5, 10, 20 and 50 cm, and the largest move. A
flip that moves little of the surface by little cannot be told by stereo depth coarser than that.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["flip_relief", "main"]

log = logging.getLogger(__name__)

THRESHOLDS_M = (0.05, 0.1, 0.2, 0.5)


def flip_relief(points: np.ndarray, centre: np.ndarray, axis: str) -> np.ndarray:
    """(S,) distance of each flipped sample of ``points`` (S, 3) to the nearest unflipped one."""
    from scipy.spatial import cKDTree

    from spacepose.flip import flip_matrix

    c = np.asarray(centre, dtype=np.float64)
    turned = (np.asarray(points, dtype=np.float64) - c) @ flip_matrix(axis).T + c
    distance, _ = cKDTree(points).query(turned)
    return distance


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.flip_relief", description=__doc__.split("\n")[0])
    p.add_argument("--target", default="tdrs")
    p.add_argument("--axis", choices=["x", "y", "z"], default="z")
    p.add_argument("--samples", type=int, default=20000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = p.parse_args(argv)
    import trimesh

    from spacepose.bundle import load_bundle
    from spacepose.tools.targets import load_target

    mesh = load_target(args.target).mesh
    points, _ = trimesh.sample.sample_surface(mesh, int(args.samples), seed=int(args.seed))
    bundle = load_bundle(None)
    centre = bundle.centre if bundle.target_name == args.target else np.asarray(mesh.bounds).mean(axis=0)
    d = flip_relief(np.asarray(points), centre, args.axis)
    shares = {f"moved_over_{t:g}m": float(np.mean(d > t)) for t in THRESHOLDS_M}
    out = {"target": args.target, "axis": args.axis, "samples": int(args.samples), **shares, "max_m": float(d.max())}
    print(f"{args.target}, half turn about body {args.axis}: " + ", ".join(
        f"{100 * v:.1f} % of the surface moved > {k.split('_')[-1]}" for k, v in shares.items()) + f"; at most {d.max():.2f} m")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(main())
