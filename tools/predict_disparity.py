"""Cache the runtime stereo stage's disparity for every frame of a dataset (paper §4 protocol).

``predict_disparity(DATASET, GRAPH)`` runs :class:`spacepose.stereo_stage.StereoMatcher` — the
flight code, coarse letterboxed pass then the ROI fine pass — on each (rectified) pair and writes
``DATASET/pred_disparity/<name>.pfm`` (float32, full resolution, 0 where unknown). Resumable: an
existing file is skipped (``overwrite=False``); every file is written atomically. The pose network
trains on these maps (``PoseDataConfig(depth_source="stereo")``).

CLI: ``python -m spacepose.tools.predict_disparity DATASET --graph BUNDLE_DIR_or_stereo.onnx``
(``spacepose train-pose --stereo-graph`` calls it too).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import time
from pathlib import Path
from typing import Callable

import numpy as np

from spacepose.errors import DatasetError
from spacepose.imageio import read_image, read_pfm, write_pfm

log = logging.getLogger(__name__)

__all__ = ["predict_disparity", "resolve_stereo_graph", "main"]

PRED_DISPARITY_DIR = "pred_disparity"


def resolve_stereo_graph(graph: str | os.PathLike) -> tuple[Path, float]:
    """(stereo.onnx path, ROI window margin) of a bundle folder or a stereo graph file."""
    path = Path(graph)
    margin = 1.25
    if path.is_dir():
        manifest = path / "bundle.json"
        file = "stereo.onnx"
        if manifest.is_file():
            stereo = json.loads(manifest.read_text(encoding="utf-8")).get("stereo", {})
            file = stereo.get("file", file)
            margin = float(stereo.get("window_margin", margin))
        path = path / file
    if not path.is_file():
        raise DatasetError(f"stereo graph not found: {path}")
    return path, margin


def predict_disparity(dataset: str | os.PathLike, graph: str | os.PathLike, *, frames: list[str] | None = None,
                      limit: int | None = None, threads: int = 2, overwrite: bool = False,
                      progress: Callable[[int, int], None] | None = None) -> dict:
    """Write ``pred_disparity/<name>.pfm`` for the frames of ``dataset`` (all, or ``frames``).

    Returns ``{"written", "skipped", "dir", "graph", "seconds"}``.
    """
    from spacepose.calibration.rectify import rectify
    from spacepose.calibration.rig import load_rig
    from spacepose.stereo_stage import StereoMatcher
    from spacepose.tools.pose_data import read_pose_labels

    root = Path(dataset)
    if frames is None:
        frames = [r.frame for r in read_pose_labels(root)]
    if limit is not None:
        frames = frames[: int(limit)]
    out_dir = root / PRED_DISPARITY_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    todo = [f for f in frames if overwrite or not (out_dir / f"{f}.pfm").is_file()]
    skipped = len(frames) - len(todo)
    graph_path, margin = resolve_stereo_graph(graph)
    t0 = time.perf_counter()
    if todo:
        rect = rectify(load_rig(root / "rig.yaml"))
        matcher = StereoMatcher(graph_path, threads=threads, margin=margin)
        (out_dir / "source.json").write_text(json.dumps({"graph": str(graph_path), "window_margin": margin,
                                                         "metadata": matcher.metadata}, indent=2, default=str))
        for i, name in enumerate(todo, 1):
            left = read_image(root / "left" / f"{name}.png")
            right = read_image(root / "right" / f"{name}.png")
            if not rect.is_identity:
                left, right = rect.rectify_pair(left, right)
            disp = matcher.match(left, right).disparity.astype(np.float32)
            tmp = out_dir / f".{name}.pfm.tmp"
            write_pfm(tmp, disp)
            os.replace(tmp, out_dir / f"{name}.pfm")
            if progress:
                progress(i, len(todo))
    seconds = time.perf_counter() - t0
    log.info("predicted %d disparities (%d cached) in %.1f s", len(todo), skipped, seconds)
    return {"written": len(todo), "skipped": skipped, "dir": str(out_dir), "graph": str(graph_path), "seconds": seconds}


def check_cache(dataset: str | os.PathLike, frame: str) -> np.ndarray:
    """The cached predicted disparity of one frame (DatasetError when missing)."""
    path = Path(dataset) / PRED_DISPARITY_DIR / f"{frame}.pfm"
    if not path.is_file():
        raise DatasetError(f"no predicted disparity {path}")
    return read_pfm(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spacepose.tools.predict_disparity", description=__doc__.split("\n")[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--graph", type=Path, required=True, help="bundle folder or stereo.onnx")
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--overwrite", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    result = predict_disparity(args.dataset, args.graph, limit=args.limit, threads=args.threads, overwrite=args.overwrite,
                               progress=lambda i, n: print(f"\r{i}/{n}", end="", flush=True))
    print(f"\nwrote {result['written']}, skipped {result['skipped']} -> {result['dir']} ({result['seconds']:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
