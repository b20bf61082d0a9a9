"""Session 26: the run time of ``spacepose.silhouette.align_centroid`` on the default bundle's outline samples.

    python reports/position_s26/time_align.py [--calls 200]

A 1280x960 paper-rig camera (f = 1600 px), the target 30 m ahead filling a 400-px window, the window seen as the
bundle's silhouette frame; prints the mean time of one call.
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    from spacepose.bundle import load_bundle
    from spacepose.silhouette import align_centroid, silhouette_frame, splat_mask

    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=200)
    calls = ap.parse_args().calls
    bundle = load_bundle(None)
    points = np.ascontiguousarray(bundle.silhouette_points, dtype=np.float32)
    K = np.array([[1600.0, 0.0, 639.5], [0.0, 1600.0, 479.5], [0.0, 0.0, 1.0]])
    R, t = np.eye(3), np.array([0.2, 0.1, 30.0])
    frame = silhouette_frame(K, 440, 280, 400, bundle.silhouette.max_side_px)
    observed, _, _ = splat_mask(points, R, t + [0.1, 0.0, 0.0], frame)
    for _ in range(3):
        align_centroid(R, t, points, observed, frame)
    t0 = time.perf_counter()
    for _ in range(calls):
        align_centroid(R, t, points, observed, frame)
    print(f"align_centroid: {(time.perf_counter() - t0) / calls * 1e3:.2f} ms a call "
          f"({frame.size}-px frame, {len(points)} outline samples)")


if __name__ == "__main__":
    main()
