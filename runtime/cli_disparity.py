"""``spacepose disparity FOLDER --calib RIG --out DIR``: TSCA-Stereo disparity for an image folder.

Reads ``FOLDER/left/<name>`` and ``FOLDER/right/<name>`` pairs, rectifies them with the rig, runs the
stereo stage (coarse pass -> ROI -> fine pass) and writes ``DIR/<stem>.pfm``: float32 disparity of the
left rectified image at the input resolution, 0 where unknown. A frame that cannot be read or does
not fit the rig is logged and skipped; the run goes on. Existing outputs are never overwritten
without ``--force``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

HELP = "disparity maps (PFM) of the left rectified images of a left/ right/ folder"

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


def default_stereo_graph() -> Path:
    """runtime/bundles/default/stereo.onnx (the shipped default bundle)."""
    return Path(__file__).resolve().parent / "bundles" / "default" / "stereo.onnx"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="sequence folder with left/ and right/ subfolders")
    parser.add_argument("--calib", type=Path, required=True, help="rig calibration (OpenCV FileStorage YAML/XML/JSON)")
    parser.add_argument("--out", type=Path, required=True, help="output folder for <name>.pfm")
    parser.add_argument("--bundle", type=Path, default=None, help="model bundle folder (default: the shipped one)")
    parser.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op threads (default 2)")
    parser.add_argument("--force", action="store_true", help="overwrite existing .pfm files")


def list_pairs(folder: Path) -> list[tuple[str, Path, Path]]:
    """(name, left path, right path) for every left image that has a right image of the same name."""
    from .errors import DatasetError

    left_dir, right_dir = folder / "left", folder / "right"
    if not left_dir.is_dir() or not right_dir.is_dir():
        raise DatasetError(f"{folder} must contain left/ and right/ subfolders")
    pairs = []
    for lp in sorted(left_dir.iterdir()):
        if lp.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        rp = right_dir / lp.name
        if not rp.exists():
            log.warning("%s: no right image %s; skipped", lp.name, rp)
            continue
        pairs.append((lp.stem, lp, rp))
    return pairs


def run(args: argparse.Namespace) -> int:
    from .calibration.rectify import rectify
    from .calibration.rig import load_rig
    from .errors import BundleError, CalibrationError, DatasetError, ImageReadError, ShapeError
    from .imageio import read_image, write_pfm
    from .stereo_stage import StereoMatcher

    graph = (args.bundle / "stereo.onnx") if args.bundle is not None else default_stereo_graph()
    if not graph.is_file():
        raise BundleError(f"stereo graph not found: {graph} (export one with `spacepose export-stereo`)")
    pairs = list_pairs(args.folder)
    if not pairs:
        raise DatasetError(f"no left/right image pairs in {args.folder}")
    out_dir: Path = args.out
    existing = [out_dir / f"{name}.pfm" for name, _, _ in pairs if (out_dir / f"{name}.pfm").exists()]
    if existing and not args.force:
        raise DatasetError(f"{len(existing)} output file(s) exist already (e.g. {existing[0]}); use --force to overwrite")
    rig = load_rig(args.calib)
    rectification = rectify(rig)
    tiles, margin = 1, 1.25
    if (graph.parent / "bundle.json").is_file():   # the graph's bundle: its window margin and, for this
        from .bundle import load_bundle            # rig, the coarse pass's tiles (PoseEstimator does the same)

        bundle = load_bundle(graph.parent, verify_graphs=False)
        tiles, margin = bundle.coarse_tiles_for(rig), bundle.stereo.window_margin
    matcher = StereoMatcher(graph, threads=args.threads, coarse_tiles=tiles, margin=margin)
    out_dir.mkdir(parents=True, exist_ok=True)

    done, failed = 0, 0
    for name, lp, rp in pairs:
        try:
            left, right = read_image(lp), read_image(rp)
            if left.shape != right.shape:
                raise ShapeError(f"left {left.shape} and right {right.shape} differ")
            rig.check_image_size(left.shape)
            left_r, right_r = rectification.rectify_pair(left, right)
            result = matcher.match(left_r, right_r)
            write_pfm(out_dir / f"{name}.pfm", result.disparity)
        except (ImageReadError, ShapeError, CalibrationError) as err:
            failed += 1
            log.error("%s: skipped: %s", name, err)
            print(f"{name}: skipped: {err}", file=sys.stderr)
            continue
        done += 1
        log.info("%s: %s, %.0f ms", name, result.status, result.timings_ms.get("total_ms", float("nan")))
    print(f"wrote {done} disparity map(s) to {out_dir}" + (f"; skipped {failed} frame(s)" if failed else ""))
    return 0 if failed == 0 else 1
