"""Evaluate the stereo stage on the test split: ours (runtime StereoMatcher) vs OpenCV StereoSGBM.

Metrics (paper §5.1) over *target pixels* (``mask & gt > 0``) of full test frames: EPE, RMSE, bad-1,
bad-3 (%) and D1 (%, error > 3 px and > 5 % of GT). Aggregated pixel-weighted — as if all target
pixels of all frames were one set — overall, per illumination regime and per distance bin (z of t:
10-20, 20-30, 30-40, 40-50 m), and split by region: ``region:silhouette`` (target pixels within
:data:`SILHOUETTE_RADIUS` px of a non-target pixel, where a coarse-to-fine network blurs the outline
into the background) and ``region:interior`` (the rest). A pixel with no estimate (SGBM invalid,
outside our window) counts with disparity 0, i.e. as an error; the density of each method is
reported next to it.

Classical baseline: ``cv2.StereoSGBM`` in ``MODE_SGBM_3WAY`` on the grey images with
:data:`SGBM_DEFAULTS` (P1 = 8·bs², P2 = 32·bs² for one channel, per the OpenCV docs) and
``numDisparities`` covering the rig's range (``f·B / z_min`` plus 10 %, rounded up to 16).
``tune_sgbm`` grid-searches block size and uniqueness on training frames (``--tune-sgbm N``).
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Iterable

import cv2
import numpy as np

from spacepose.metrics import stereo_metrics
from spacepose.tools.stereo_data import FrameRecord, read_labels

log = logging.getLogger(__name__)

__all__ = ["SGBMParams", "SGBM_DEFAULTS", "sgbm_disparity", "sgbm_for_rig", "tune_sgbm", "MetricAccumulator",
           "DISTANCE_BINS", "evaluate_stereo", "format_table", "save_figure"]

DISTANCE_BINS = ((10.0, 20.0), (20.0, 30.0), (30.0, 40.0), (40.0, 50.0))
METRIC_KEYS = ("epe", "rmse", "bad1", "bad3", "d1")


@dataclass(frozen=True)
class SGBMParams:
    """StereoSGBM parameters (P1/P2 derived from the block size, one grey channel)."""

    num_disparities: int = 96
    block_size: int = 5
    uniqueness_ratio: int = 10
    speckle_window_size: int = 100
    speckle_range: int = 2
    disp12_max_diff: int = 1
    pre_filter_cap: int = 63
    mode: str = "SGBM_3WAY"

    @property
    def p1(self) -> int:
        return 8 * self.block_size ** 2

    @property
    def p2(self) -> int:
        return 32 * self.block_size ** 2


#: documented defaults (REFERENCES "Classical baseline": P1 = 8·cn·bs², P2 = 32·cn·bs², uniqueness 5-15,
#: speckle window 50-200); num_disparities is replaced by :func:`sgbm_for_rig`.
SGBM_DEFAULTS = SGBMParams()


def sgbm_for_rig(focal_px: float, baseline_m: float, z_min: float = 10.0, base: SGBMParams = SGBM_DEFAULTS) -> SGBMParams:
    """``base`` with ``num_disparities`` covering disparities up to ``1.1 · f·B / z_min``."""
    d_max = 1.1 * focal_px * baseline_m / z_min
    return replace(base, num_disparities=int(16 * math.ceil(d_max / 16.0)))


def _grey(image: np.ndarray) -> np.ndarray:
    if image.dtype == np.uint16:
        image = (image / 257.0).astype(np.uint8)
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return image


def sgbm_disparity(left: np.ndarray, right: np.ndarray, params: SGBMParams) -> np.ndarray:
    """StereoSGBM disparity (float32 px), 0 where SGBM has no estimate."""
    mode = {"SGBM": cv2.STEREO_SGBM_MODE_SGBM, "SGBM_3WAY": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
            "HH": cv2.STEREO_SGBM_MODE_HH}[params.mode]
    matcher = cv2.StereoSGBM_create(minDisparity=0, numDisparities=params.num_disparities, blockSize=params.block_size,
                                    P1=params.p1, P2=params.p2, disp12MaxDiff=params.disp12_max_diff,
                                    preFilterCap=params.pre_filter_cap, uniquenessRatio=params.uniqueness_ratio,
                                    speckleWindowSize=params.speckle_window_size, speckleRange=params.speckle_range,
                                    mode=mode)
    raw = matcher.compute(_grey(left), _grey(right)).astype(np.float32) / 16.0
    raw[raw <= 0] = 0.0
    return raw


class MetricAccumulator:
    """Pixel-weighted aggregation of per-frame :func:`spacepose.metrics.stereo_metrics`."""

    def __init__(self) -> None:
        self.n = 0
        self.frames = 0
        self.dense = 0
        self.sums = {k: 0.0 for k in METRIC_KEYS}

    def add(self, pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> None:
        n = int(valid.sum())
        if n == 0:
            return
        m = stereo_metrics(pred, gt, valid)
        self.frames += 1
        self.n += n
        self.dense += int((valid & (pred > 0)).sum())
        for k in METRIC_KEYS:
            v = m[k] ** 2 if k == "rmse" else m[k]
            self.sums[k] += v * n

    def result(self) -> dict[str, float]:
        if self.n == 0:
            return {**{k: float("nan") for k in METRIC_KEYS}, "pixels": 0, "frames": 0, "density": float("nan")}
        out = {k: self.sums[k] / self.n for k in METRIC_KEYS}
        out["rmse"] = math.sqrt(out["rmse"])
        out.update(pixels=self.n, frames=self.frames, density=100.0 * self.dense / self.n)
        return out


#: Chebyshev radius (px) of the ``region:silhouette`` band; the training's ``--edge-radius`` default
SILHOUETTE_RADIUS = 3


def silhouette_band(valid: np.ndarray, radius: int = SILHOUETTE_RADIUS) -> np.ndarray:
    """(H, W) bool: ``valid`` pixels within ``radius`` px (Chebyshev) of a non-valid pixel.

    The image border does not count as background (erosion pads with the maximum).
    """
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    interior = cv2.erode(valid.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=1) > 0
    return valid & ~interior


def _groups(rec: FrameRecord) -> Iterable[str]:
    yield "overall"
    yield f"regime:{rec.regime}"
    for lo, hi in DISTANCE_BINS:
        if lo <= rec.distance_m < hi or (hi == DISTANCE_BINS[-1][1] and rec.distance_m == hi):
            yield f"distance:{lo:g}-{hi:g}m"


def _load_test_frame(root: Path, rec: FrameRecord):
    from spacepose.imageio import read_image, read_pfm

    left = read_image(root / "left" / f"{rec.frame}.png")
    right = read_image(root / "right" / f"{rec.frame}.png")
    gt = np.nan_to_num(read_pfm(root / "disparity" / f"{rec.frame}.pfm"), nan=0.0, posinf=0.0, neginf=0.0)
    mask = read_image(root / "mask" / f"{rec.frame}.png")
    if mask.ndim == 3:
        mask = mask[..., 0]
    return left, right, gt.astype(np.float32), (mask > 0) & (gt > 0)


def tune_sgbm(root: str | Path, base: SGBMParams, n_frames: int = 8,
              block_sizes: tuple[int, ...] = (3, 5, 7, 9), uniqueness: tuple[int, ...] = (5, 10, 15)) -> tuple[SGBMParams, list[dict]]:
    """Grid search on training frames (EPE over target pixels) -> (best params, all trials)."""
    root = Path(root)
    recs = read_labels(root, "train")[:n_frames]
    frames = [_load_test_frame(root, r) for r in recs]
    trials = []
    for bs in block_sizes:
        for u in uniqueness:
            p = replace(base, block_size=bs, uniqueness_ratio=u)
            acc = MetricAccumulator()
            for left, right, gt, valid in frames:
                acc.add(sgbm_disparity(left, right, p), gt, valid)
            trials.append({"params": asdict(p), **acc.result()})
    best = min(trials, key=lambda t: (t["epe"] if math.isfinite(t["epe"]) else float("inf")))
    return SGBMParams(**best["params"]), trials


def _frame_row(rec: FrameRecord, ours: np.ndarray, sgbm: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> dict[str, Any]:
    """Per-frame diagnosis: mean and median error on target pixels, and the share left at 0 (no estimate)."""
    row: dict[str, Any] = {"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m,
                           "gt_median": float(np.median(gt[valid])) if valid.any() else float("nan")}
    for name, pred in (("ours", ours), ("sgbm", sgbm)):
        err = np.abs(np.nan_to_num(pred[valid], nan=0.0) - gt[valid])
        row[name] = {"epe": float(err.mean()) if err.size else float("nan"),
                     "median": float(np.median(err)) if err.size else float("nan"),
                     "zero_share": float(np.mean(pred[valid] <= 0)) if err.size else float("nan")}
    return row


def evaluate_stereo(dataset: str | Path, graph: str | Path, *, limit: int | None = None, threads: int = 2,
                    sgbm: SGBMParams | None = None, figure: str | Path | None = None,
                    n_figure: int = 4) -> dict[str, Any]:
    """Run ours and SGBM on the test split; returns the JSON-able report (also used by the CLI)."""
    from spacepose.calibration.rectify import rectify
    from spacepose.calibration.rig import load_rig
    from spacepose.stereo_stage import StereoMatcher

    root = Path(dataset)
    recs = read_labels(root, "test")
    if limit is not None:
        recs = recs[: int(limit)]
    rig = load_rig(root / "rig.yaml")
    rect = rectify(rig)
    params = sgbm or sgbm_for_rig(rect.focal_px, rect.baseline_m)
    matcher = StereoMatcher(graph, threads=threads)
    acc: dict[str, dict[str, MetricAccumulator]] = {"ours": {}, "sgbm": {}}
    times = {"ours": [], "sgbm": []}
    fig_rows: list[dict] = []
    frame_rows: list[dict[str, Any]] = []
    seen_regimes: set[str] = set()
    for rec in recs:
        left, right, gt, valid = _load_test_frame(root, rec)
        left_r, right_r = rect.rectify_pair(left, right)
        band = silhouette_band(valid)
        t0 = time.perf_counter()
        ours = matcher.match(left_r, right_r).disparity
        t1 = time.perf_counter()
        classic = sgbm_disparity(left_r, right_r, params)
        t2 = time.perf_counter()
        times["ours"].append((t1 - t0) * 1e3)
        times["sgbm"].append((t2 - t1) * 1e3)
        for name, pred in (("ours", ours), ("sgbm", classic)):
            for g in _groups(rec):
                acc[name].setdefault(g, MetricAccumulator()).add(pred, gt, valid)
            for g, region in (("region:silhouette", band), ("region:interior", valid & ~band)):
                acc[name].setdefault(g, MetricAccumulator()).add(pred, gt, region)
        frame_rows.append(_frame_row(rec, ours, classic, gt, valid))
        if figure is not None and len(fig_rows) < n_figure and rec.regime not in seen_regimes and valid.any():
            seen_regimes.add(rec.regime)
            fig_rows.append({"frame": rec.frame, "regime": rec.regime, "distance": rec.distance_m, "left": left_r,
                             "gt": gt, "valid": valid, "ours": ours, "sgbm": classic})
    report = {
        "dataset": str(root), "graph": str(graph), "frames": len(recs), "threads": threads,
        "graph_metadata": {k: matcher.metadata.get(k) for k in ("input_size", "iters", "variant", "max_disp",
                                                                 "training_commit", "dataset")},
        "sgbm_params": {**asdict(params), "P1": params.p1, "P2": params.p2},
        "latency_ms_median": {k: float(np.median(v)) if v else float("nan") for k, v in times.items()},
    }
    report["per_frame"] = frame_rows
    for name in ("ours", "sgbm"):
        report[name] = {g: a.result() for g, a in sorted(acc[name].items(), key=lambda kv: _group_order(kv[0]))}
    if figure is not None and fig_rows:
        save_figure(fig_rows, figure)
        report["figure"] = str(figure)
    return report


def _group_order(name: str) -> tuple[int, str]:
    rank = {"overall": 0, "regime": 1, "distance": 2, "region": 3}.get(name.split(":")[0], 4)
    return (rank, name)


def format_table(report: dict[str, Any]) -> str:
    """Markdown table: one row per (group, method)."""
    lines = ["| group | method | EPE px | RMSE px | bad-1 % | bad-3 % | D1 % | density % | pixels |",
             "|---|---|---|---|---|---|---|---|---|"]
    for group in report["ours"]:
        for name in ("ours", "sgbm"):
            m = report[name].get(group)
            if m is None:
                continue
            lines.append(f"| {group} | {name} | {m['epe']:.3f} | {m['rmse']:.3f} | {m['bad1']:.2f} | {m['bad3']:.2f} "
                         f"| {m['d1']:.2f} | {m['density']:.1f} | {m['pixels']} |")
    return "\n".join(lines)


def save_figure(rows: list[dict], path: str | Path) -> None:
    """Fig.13-like panel: left | GT | ours | SGBM | |err| ours | |err| SGBM, cropped around the target."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from spacepose.roi import bbox_from_mask

    cols = ["left (rectified)", "ground truth", "ours (TSCA-Stereo)", "StereoSGBM", "|error| ours", "|error| SGBM"]
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(3.0 * len(cols), 2.6 * len(rows)), squeeze=False)
    for r, row in enumerate(rows):
        h, w = row["gt"].shape
        x0, y0, x1, y1 = bbox_from_mask(row["valid"]) or (0, 0, w, h)
        pad = int(0.15 * max(x1 - x0, y1 - y0)) + 4
        sl = (slice(max(0, y0 - pad), min(h, y1 + pad)), slice(max(0, x0 - pad), min(w, x1 + pad)))
        vmax = float(np.percentile(row["gt"][row["valid"]], 99)) * 1.1 if row["valid"].any() else 1.0
        err_o = np.where(row["valid"], np.abs(row["ours"] - row["gt"]), np.nan)
        err_s = np.where(row["valid"], np.abs(row["sgbm"] - row["gt"]), np.nan)
        panels = [row["left"], np.where(row["valid"], row["gt"], np.nan), row["ours"], row["sgbm"], err_o, err_s]
        for c, img in enumerate(panels):
            ax = axes[r, c]
            crop = img[sl]
            if c == 0:
                ax.imshow(crop, cmap="gray" if crop.ndim == 2 else None)
            elif c < 4:
                ax.imshow(crop, cmap="magma", vmin=0, vmax=vmax)
            else:
                ax.imshow(crop, cmap="inferno", vmin=0, vmax=3.0)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(cols[c], fontsize=9)
        axes[r, 0].set_ylabel(f"{row['regime']}, {row['distance']:.0f} m", fontsize=9)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(report: dict[str, Any], out_dir: str | Path) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "stereo_eval.json"
    path.write_text(json.dumps(report, indent=2, default=float))
    (out / "stereo_eval.md").write_text(format_table(report) + "\n")
    return path
