"""Session 39: the three sped-up steps of the runtime, old code against new, on the calls of real frames.

    python reports/profile_s39/micro.py data/tdrs1280_eval 20 [--rev 11c3a97]

Runs the estimator (the shipped bundle) over the first N frames of FOLDER and records every ``refine_outline`` and
``knn_indices`` call (a refinement's ``edges`` left out: both make their own). The modules as they were at ``--rev`` (``git show``, loaded beside this checkout's) then replay
the same calls: the script prints whether every output is the same, and the time per call of both, interleaved, best
of ``--reps`` rounds (a machine whose speed drifts slows both alike). Also ``splat_mask`` on the refinements' poses.
"""
from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _module_at(rev: str, name: str, folder: Path):
    """``runtime/<name>.py`` as of ``rev``, loaded as ``spacepose._at_rev_<name>`` (its relative imports resolve to
    this checkout's ``spacepose`` package)."""
    src = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:runtime/{name}.py"], capture_output=True,
                         text=True, check=True).stdout
    path = folder / f"{name}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location(f"spacepose._at_rev_{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _record(folder: Path, n: int) -> tuple[list, list]:
    import spacepose.pose_inputs as pose_inputs
    import spacepose.silhouette as silhouette
    from spacepose.cli_estimate import list_frames, read_pair
    from spacepose.estimator import PoseEstimator

    refine, knn = [], []
    originals = {"refine_outline": silhouette.refine_outline, "knn_indices": pose_inputs.knn_indices}

    def recorder(name, store):
        def call(*a, **k):
            store.append((a, {key: v for key, v in k.items() if key != "edges"}))   # the old code makes its own
            return originals[name](*a, **k)
        return call

    patched = {"refine_outline": recorder("refine_outline", refine), "knn_indices": recorder("knn_indices", knn)}
    for module in [m for name, m in sys.modules.items() if name.startswith("spacepose")]:
        for name, original in originals.items():
            if getattr(module, name, None) is original:
                setattr(module, name, patched[name])
    try:
        est = PoseEstimator(folder / "rig.yaml", threads=2)
        for frame in list_frames(folder)[:n]:
            est.estimate(*read_pair(folder, frame))
    finally:
        for module in [m for name, m in sys.modules.items() if name.startswith("spacepose")]:
            for name, original in originals.items():
                if getattr(module, name, None) is patched[name]:
                    setattr(module, name, original)
    return refine, knn


def _ab(label: str, old, new, n_calls: int, reps: int) -> None:
    best = {"old": float("inf"), "new": float("inf")}
    for _ in range(reps):
        for key, f in (("old", old), ("new", new)):
            t0 = time.perf_counter()
            f()
            best[key] = min(best[key], time.perf_counter() - t0)
    print(f"{label}: old {1e3 * best['old'] / n_calls:.3f} ms a call, new {1e3 * best['new'] / n_calls:.3f} ms "
          f"(x{best['old'] / best['new']:.2f}), {n_calls} calls")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("folder", type=Path)
    p.add_argument("frames", type=int)
    p.add_argument("--rev", default="11c3a97", help="the old code's commit")
    p.add_argument("--reps", type=int, default=5)
    args = p.parse_args(argv)
    import spacepose.pose_inputs as new_knn
    import spacepose.silhouette as new_sil

    refine, knn = _record(args.folder, args.frames)
    with tempfile.TemporaryDirectory() as tmp:
        old_sil = _module_at(args.rev, "silhouette", Path(tmp))
        old_knn = _module_at(args.rev, "pose_inputs", Path(tmp))
        same_fit = lambda a, b: (np.array_equal(a.R, b.R) and np.array_equal(a.t, b.t)  # noqa: E731
                                 and a.chamfer_px == b.chamfer_px and a.points_res == b.points_res)
        fits = sum(same_fit(old_sil.refine_outline(*a, **k), new_sil.refine_outline(*a, **k)) for a, k in refine)
        print(f"refine_outline: {fits} of {len(refine)} recorded calls give the same fit")
        nbrs = sum(np.array_equal(old_knn.knn_indices(*a, **k), new_knn.knn_indices(*a, **k)) for a, k in knn)
        print(f"knn_indices: {nbrs} of {len(knn)} recorded calls give the same neighbours")
        splats = [(a[2], a[0], a[1], a[4]) for a, _ in refine]       # points, R, t, frame of each refinement
        same = sum(all(np.array_equal(x, y) for x, y in zip(old_sil.splat_mask(*s), new_sil.splat_mask(*s)))
                   for s in splats)
        print(f"splat_mask: {same} of {len(splats)} splats the same")
        _ab("splat_mask", lambda: [old_sil.splat_mask(*s) for s in splats],
            lambda: [new_sil.splat_mask(*s) for s in splats], len(splats), args.reps)
        _ab("refine_outline", lambda: [old_sil.refine_outline(*a, **k) for a, k in refine],
            lambda: [new_sil.refine_outline(*a, **k) for a, k in refine], len(refine), args.reps)
        _ab("knn_indices", lambda: [old_knn.knn_indices(*a, **k) for a, k in knn],
            lambda: [new_knn.knn_indices(*a, **k) for a, k in knn], len(knn), args.reps)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
