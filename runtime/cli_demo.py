"""``spacepose demo [--count 10] [--size 1280x960]``: render a few frames, estimate, compare.

Ten frames by default: at the shipped bundle's ~27 % valid share, four frames (the default until
session 13) were often all refused, which showed the refusal but not a single pose error.

Needs the ``[train]`` extra (the renderer, ``spacepose.tools``); without it the command fails with
a :class:`~spacepose.errors.MissingExtraError` naming the extra.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from spacepose.cli_args import size_type

HELP = "render a few frames of the bundle's target, estimate their poses and print the errors"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--count", type=int, default=10, help="frames to render (default 10)")
    parser.add_argument("--size", type=size_type(16), default=(1280, 960), help="image size WIDTHxHEIGHT (default 1280x960)")
    parser.add_argument("--seed", type=int, default=0, help="scene seed (default 0)")
    parser.add_argument("--bundle", type=Path, default=None, help="model bundle folder (default: the shipped one)")
    parser.add_argument("--threads", type=int, default=2, help="onnxruntime threads per graph")


def run(args: argparse.Namespace) -> int:
    from ._optional import import_optional

    import_optional("trimesh")
    import_optional("spacepose.tools.render")
    from .bundle import load_bundle
    from .calibration.rig import paper_rig
    from .estimator import PoseEstimator
    from .metrics import rotation_error_deg, translation_error
    from .tools.dataset import render_frame
    from .tools.render import PoseSampler, StereoCamera
    from .tools.targets import load_target

    bundle = load_bundle(args.bundle)
    rig = paper_rig(*args.size)
    target = load_target(bundle.target_name)
    camera = StereoCamera.from_rig(rig)
    sampler = PoseSampler(camera, target.bounding_radius, bundle.distance_range_m)
    estimator = PoseEstimator(rig, bundle=bundle, threads=args.threads, use_prior=False)
    import numpy as np

    print(f"{'frame':<8}{'regime':<10}{'z m':>7}{'e_t m':>9}{'e_R deg':>9}{'valid':>7}  {'status':<15}{'conf':>6}"
          f"{'e_pos m':>9}{'ms':>8}")
    errors_t, errors_r, errors_pos, n_valid = [], [], [], 0
    centre = np.asarray(bundle.centre, dtype=np.float64)
    for index in range(max(args.count, 0)):
        frame = render_frame(target, camera, sampler, args.seed, index)
        label = frame.label
        result = estimator.estimate(frame.left, frame.right)
        total_ms = sum(result.timings_ms.values())
        if result.valid:
            e_t = translation_error(np.asarray(label["t"]), result.t)
            e_r = rotation_error_deg(np.asarray(label["R"]), result.R)
            errors_t.append(e_t)
            errors_r.append(e_r)
            n_valid += 1
            err_text = f"{e_t:>9.3f}{e_r:>9.2f}"
        else:
            err_text = f"{'-':>9}{'-':>9}"
        pos_text = f"{'-':>9}"
        if result.position_valid:   # the target's centre, known also where the attitude is not (flip undecided)
            e_pos = float(np.linalg.norm(result.position - (np.asarray(label["R"]) @ centre + np.asarray(label["t"]))))
            errors_pos.append(e_pos)
            pos_text = f"{e_pos:>9.3f}"
        print(f"{frame.name:<8}{label['regime']:<10}{label['t'][2]:>7.1f}{err_text}{str(result.valid):>7}  "
              f"{result.status:<15}{result.confidence:>6.2f}{pos_text}{total_ms:>8.0f}")
    print(f"summary: {n_valid}/{args.count} valid", end="")
    if errors_t:
        print(f"; mean e_t {np.mean(errors_t):.3f} m, mean e_R {np.mean(errors_r):.2f} deg "
              f"(median {np.median(errors_t):.3f} m, {np.median(errors_r):.2f} deg)")
    else:
        print()
    print(f"target position (with or without the attitude): {len(errors_pos)}/{args.count}", end="")
    print(f"; mean e_pos {np.mean(errors_pos):.3f} m (median {np.median(errors_pos):.3f} m)" if errors_pos else "")
    return 0
