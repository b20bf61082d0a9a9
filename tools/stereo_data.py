"""Training samples for TSCA-Stereo from a rendered dataset (layout of CONVENTIONS.md).

Every sample is one fixed-size view (default 256x256) of a 640x480 frame pair, made with the same
geometry as the flight runtime (``spacepose.roi``):

* with probability ``roi_prob`` (~0.75) a square ROI window around the target — the mask box ∪ the
  box shifted by ``-d`` (its copy in the right image), random margin 1.05–1.6 and centre jitter, so
  the scale ``s = size / side`` varies from sample to sample;
* otherwise the whole frame letterboxed (the runtime's coarse pass).

Ground-truth disparity is resampled with nearest neighbour and multiplied by ``s``;
``valid = mask & d > 0`` after resampling. Photometric augmentation (train only): per-image
(asymmetric) brightness, contrast and gamma, Gaussian noise, and occasional conversion to grey.
With ``photometric="wide"`` each sample first gets one look shared by both views
(:func:`wide_look`): a tone curve, a colour tint, an exposure gain that clips, and an optics blur,
drawn wider than the renderer's own range so that another renderer's images fall inside it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import cv2
import numpy as np

from spacepose import roi
from spacepose.errors import DatasetError
from spacepose.imageio import read_image, read_pfm
from spacepose.tools.labels import FrameLabel, read_labels

log = logging.getLogger(__name__)

__all__ = ["FrameRecord", "read_labels", "StereoCropConfig", "StereoCropDataset", "photometric_augment",
           "PHOTOMETRIC_MODES", "sample_wide_look", "wide_look",
           "oversample_records"]


#: the stereo samples' name of the shared label record (only ``frame``, ``split``, ``regime`` and
#: ``distance_m`` are used here)
FrameRecord = FrameLabel


@dataclass(frozen=True)
class StereoCropConfig:
    """How samples are cut (serialised into the training config)."""

    size: tuple[int, int] = (256, 256)
    roi_prob: float = 0.75
    margin_range: tuple[float, float] = (1.05, 1.6)
    jitter: float = 0.1
    min_side: int = 32
    max_disp: float = 96.0
    augment: bool = True
    grey_prob: float = 0.1
    noise_sigma_max: float = 4.0
    #: supervise background pixels with their true disparity 0 (sky, stars and the Earth are at
    #: infinity for this rig): the coarse pass finds the target by thresholding disparity, so the
    #: network must learn to output 0 off the target, not only to be right on it
    supervise_background: bool = True
    #: random sub-crop (w, h) of each training sample, containing the target centre when it can;
    #: None trains on the whole graph-sized sample. Matching is translation invariant, so smaller
    #: crops buy steps on a CPU without changing the disparity distribution the graph sees.
    train_crop: tuple[int, int] | None = None
    #: "mild": the per-view jitter of :func:`photometric_augment` only (sessions 1-35); "wide": before it,
    #: one look per sample shared by both views (:func:`wide_look`), with probability ``wide_prob``
    photometric: str = "mild"
    wide_prob: float = 0.8

    def __post_init__(self) -> None:
        if self.photometric not in PHOTOMETRIC_MODES:
            raise ValueError(f"photometric must be one of {PHOTOMETRIC_MODES}, got {self.photometric!r}")
        if not 0.0 <= self.wide_prob <= 1.0:
            raise ValueError(f"wide_prob must be in [0, 1], got {self.wide_prob}")


PHOTOMETRIC_MODES = ("mild", "wide")


def sample_wide_look(rng: np.random.Generator) -> dict[str, Any]:
    """One sample's look for :func:`wide_look`: tone-curve gamma log-uniform in 0.4-2.5, per-channel tint
    0.75-1.25, exposure gain 0.5-1.8 (clipped at white), Gaussian blur sigma 0-1.5 px (none below 0.25)."""
    return {"gamma": float(np.exp(rng.uniform(np.log(0.4), np.log(2.5)))),
            "tint": rng.uniform(0.75, 1.25, size=3).astype(np.float32),
            "gain": float(rng.uniform(0.5, 1.8)),
            "blur_px": float(rng.uniform(0.0, 1.5))}


def wide_look(image: np.ndarray, look: Mapping[str, Any]) -> np.ndarray:
    """``image`` (H, W, 3) float32 in [0, 255] rendered in ``look`` (:func:`sample_wide_look`): another
    renderer's tone mapping and colour balance, another exposure (what it pushes past white is lost), and
    softer optics. Applied with the same look to both views of a sample; returns (H, W, 3) float32 in [0, 255]."""
    if image.ndim != 3 or image.shape[2] != 3:
        raise DatasetError(f"wide_look takes (H, W, 3) images, got {image.shape}")
    x = np.clip(image / 255.0, 0.0, 1.0) ** np.float32(look["gamma"])
    x = np.clip(x * np.asarray(look["tint"], np.float32) * np.float32(look["gain"]), 0.0, 1.0)
    if look["blur_px"] > 0.25:
        x = cv2.GaussianBlur(x.astype(np.float32), (0, 0), float(look["blur_px"]))
    return (x * 255.0).astype(np.float32)


def photometric_augment(image: np.ndarray, rng: np.random.Generator, noise_sigma_max: float = 4.0) -> np.ndarray:
    """Brightness/contrast/gamma jitter + Gaussian noise on an (H, W, 3) float32 image in [0, 255]."""
    x = image / 255.0
    gamma = rng.uniform(0.8, 1.25)
    x = np.power(np.clip(x, 0.0, 1.0), gamma)
    contrast = rng.uniform(0.8, 1.2)
    brightness = rng.uniform(0.8, 1.2)
    mean = float(x.mean())
    x = (x - mean) * contrast + mean
    x = x * brightness + rng.uniform(-0.03, 0.03)
    x = x * 255.0
    sigma = rng.uniform(0.0, noise_sigma_max)
    if sigma > 0:
        x = x + rng.normal(0.0, sigma, size=x.shape)
    return np.clip(x, 0.0, 255.0).astype(np.float32)


def _to_rgb_float(image: np.ndarray) -> np.ndarray:
    if image.dtype == np.uint16:
        image = (image.astype(np.float32) * (255.0 / 65535.0))
    x = image.astype(np.float32)
    if x.ndim == 2:
        x = np.repeat(x[..., None], 3, axis=2)
    return x


def _random_subcrop(arrays: tuple[np.ndarray, ...], target: np.ndarray, crop: tuple[int, int],
                    rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Cut the same random (w, h) window out of every (H, W[, C]) array, holding the target centre if any."""
    h, w = target.shape
    cw, ch = min(int(crop[0]), w), min(int(crop[1]), h)
    ys, xs = np.nonzero(target)
    if len(xs):
        cx, cy = int(xs.mean()), int(ys.mean())
        x0 = int(rng.integers(max(0, cx - cw + 1), min(w - cw, cx) + 1))
        y0 = int(rng.integers(max(0, cy - ch + 1), min(h - ch, cy) + 1))
    else:
        x0 = int(rng.integers(0, w - cw + 1))
        y0 = int(rng.integers(0, h - ch + 1))
    return tuple(a[y0:y0 + ch, x0:x0 + cw] for a in arrays)


def oversample_records(records: list[FrameRecord], factors: Mapping[str, int]) -> list[FrameRecord]:
    """``records`` with every frame of regime ``r`` listed ``factors[r]`` times (others once).

    Repeated frames get different random views (the view RNG is keyed on the index), so this
    weights the hard regimes without changing the crops' distribution within a regime.
    """
    for regime, k in factors.items():
        if int(k) < 1:
            raise ValueError(f"oversample factor for {regime!r} must be >= 1, got {k}")
    known = {r.regime for r in records}
    missing = sorted(set(factors) - known)
    if missing:
        raise DatasetError(f"oversample: no frames of regime(s) {missing} (have {sorted(known)})")
    return [r for r in records for _ in range(int(factors.get(r.regime, 1)))]


class StereoCropDataset:
    """A ``torch.utils.data.Dataset`` of fixed-size stereo samples (see the module docstring).

    Items are dicts: ``left``, ``right`` (3, H, W) float32 tensors in [0, 255]; ``disparity`` (1, H, W)
    float32 net pixels; ``valid`` (1, H, W) float32 0/1; ``scale`` (float, net px per frame px);
    ``kind`` ("roi" | "letterbox"); ``regime``; ``distance`` (metres); ``frame``.

    Randomness is a pure function of (seed, epoch, index): call :meth:`set_epoch` each epoch.
    With ``augment=False`` and ``deterministic=True`` (validation) samples are fixed ROI windows.
    """

    def __init__(self, root: str | Path, split: str = "train", config: StereoCropConfig = StereoCropConfig(),
                 *, seed: int = 0, limit: int | None = None, deterministic: bool = False,
                 oversample: Mapping[str, int] | None = None) -> None:
        self.root = Path(root)
        self.config = config
        self.seed = int(seed)
        self.epoch = 0
        self.deterministic = bool(deterministic)
        self.records = read_labels(self.root, split)
        if limit is not None:
            self.records = self.records[: int(limit)]
        if not self.records:
            raise DatasetError(f"{self.root}: no frames in split {split!r}")
        if oversample:
            self.records = oversample_records(self.records, oversample)

    def __len__(self) -> int:
        return len(self.records)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def load_frame(self, rec: FrameRecord) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(left RGB, right RGB, disparity float32, mask bool) of one frame at full resolution."""
        left = read_image(self.root / "left" / f"{rec.frame}.png")
        right = read_image(self.root / "right" / f"{rec.frame}.png")
        disp = read_pfm(self.root / "disparity" / f"{rec.frame}.pfm")
        mask = read_image(self.root / "mask" / f"{rec.frame}.png")
        if mask.ndim == 3:
            mask = mask[..., 0]
        disp = np.nan_to_num(disp.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        if left.shape[:2] != disp.shape or right.shape[:2] != disp.shape or mask.shape != disp.shape:
            raise DatasetError(f"{rec.frame}: left/right/disparity/mask sizes differ")
        return left, right, disp, mask > 0

    def make_view(self, left: np.ndarray, right: np.ndarray, disp: np.ndarray, mask: np.ndarray,
                  rng: np.random.Generator | None) -> dict[str, Any]:
        """Cut one sample (numpy) out of a frame; ``rng=None`` gives the deterministic ROI view."""
        cfg = self.config
        target = mask & (disp > 0)
        bbox = roi.bbox_from_mask(target)
        use_roi = bbox is not None and (rng is None or rng.random() < cfg.roi_prob)
        if use_roi:
            d_vals = disp[target]
            d_min, d_max = float(d_vals.min()), float(d_vals.max())
            if rng is None:
                margin, jitter = 0.5 * sum(cfg.margin_range), (0.0, 0.0)
            else:
                margin = float(rng.uniform(*cfg.margin_range))
                jitter = (float(rng.uniform(-cfg.jitter, cfg.jitter)), float(rng.uniform(-cfg.jitter, cfg.jitter)))
            window = roi.square_window(bbox, d_min, d_max, margin, center_jitter=jitter, min_side=cfg.min_side,
                                       out_side=cfg.size[0], max_disp=cfg.max_disp)
            t = roi.window_transform(window, cfg.size)
            kind = "roi"
        else:
            t = roi.letterbox_transform((left.shape[1], left.shape[0]), cfg.size)
            kind = "letterbox"
        lv = roi.warp_to_net(_to_rgb_float(left), t)
        rv = roi.warp_to_net(_to_rgb_float(right), t)
        dv = roi.warp_to_net(disp, t, nearest=True) * np.float32(t.scale)
        mv = roi.warp_to_net(target.astype(np.uint8), t, nearest=True) > 0
        if cfg.supervise_background:
            valid = (mv & (dv > 0) | ~mv) & (dv < cfg.max_disp)
            dv = np.where(mv, dv, np.float32(0.0))
        else:
            valid = mv & (dv > 0) & (dv < cfg.max_disp)
        if rng is not None and cfg.augment:
            if cfg.photometric == "wide" and rng.random() < cfg.wide_prob:
                look = sample_wide_look(rng)
                lv, rv = wide_look(lv, look), wide_look(rv, look)
            lv = photometric_augment(lv, rng, cfg.noise_sigma_max)
            rv = photometric_augment(rv, rng, cfg.noise_sigma_max)
            if rng.random() < cfg.grey_prob:
                lv = np.repeat(lv.mean(axis=2, keepdims=True), 3, axis=2)
                rv = np.repeat(rv.mean(axis=2, keepdims=True), 3, axis=2)
        if rng is not None and cfg.train_crop is not None:
            lv, rv, dv, valid, mv = _random_subcrop((lv, rv, dv, valid, mv), mv, cfg.train_crop, rng)
        return {"left": lv, "right": rv, "disparity": dv.astype(np.float32), "valid": valid,
                "target": mv, "scale": float(t.scale), "kind": kind}

    def __getitem__(self, index: int) -> dict[str, Any]:
        import torch

        rec = self.records[index]
        left, right, disp, mask = self.load_frame(rec)
        rng = None if self.deterministic else np.random.default_rng([self.seed, self.epoch, int(index)])
        view = self.make_view(left, right, disp, mask, rng)
        return {
            "left": torch.from_numpy(np.ascontiguousarray(view["left"].transpose(2, 0, 1), dtype=np.float32)),
            "right": torch.from_numpy(np.ascontiguousarray(view["right"].transpose(2, 0, 1), dtype=np.float32)),
            "disparity": torch.from_numpy(view["disparity"][None].copy()),
            "valid": torch.from_numpy(view["valid"][None].astype(np.float32)),
            "target": torch.from_numpy(view["target"][None].astype(np.float32)),
            "scale": float(view["scale"]),
            "kind": view["kind"],
            "regime": rec.regime,
            "distance": rec.distance_m,
            "frame": rec.frame,
        }
