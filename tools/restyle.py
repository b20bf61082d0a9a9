"""A restyled copy of a rendered dataset: the same frames and labels, another look.

The product is judged on frames of a different renderer. This tool gives a cheap proxy for that
change: every frame's two views get one photometric style drawn per frame — a tone curve (gamma
0.5–2), a colour tint (each channel's gain 0.8–1.2), an exposure gain (0.6–1.6), an optics blur
(sigma 0–1.2 px at 640 px width) and sensor noise (sigma 0–0.04, independent per view). The geometry is
untouched, so the labels (and the masks, depths and disparities) still hold. The style is recorded per
frame in ``labels.jsonl`` under ``"restyle"``; ``dataset.json`` gains ``"restyled_from"``.

``python -m spacepose.tools.restyle SRC DST --seed S [--split test] [--limit N] [--force]``

Nothing in ``SRC`` is touched; ``DST`` must not exist unless ``--force``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import shutil
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from spacepose.errors import DatasetError
from spacepose.imageio import read_image, write_image

log = logging.getLogger(__name__)

__all__ = ["sample_style", "apply_style", "select_copy_labels", "restyle_dataset", "main"]

VIEWS = ("left", "right")


def sample_style(rng: np.random.Generator, width: int) -> dict[str, Any]:
    """One frame's style (module docstring), blur scaled to an image ``width`` px wide."""
    return {"gamma": round(math.exp(rng.uniform(math.log(0.5), math.log(2.0))), 4),
            "tint": [round(float(g), 4) for g in rng.uniform(0.8, 1.2, size=3)],
            "gain": round(float(rng.uniform(0.6, 1.6)), 4),
            "blur_px": round(float(rng.uniform(0.0, 1.2) * width / 640.0), 3),
            "noise": round(float(rng.uniform(0.0, 0.04)), 4)}


def apply_style(image: np.ndarray, style: dict[str, Any], rng: np.random.Generator) -> np.ndarray:
    """``image`` (H, W) or (H, W, 3) uint8 with ``style`` applied, uint8 of the same shape.

    Order: tone curve and tint (the renderer's look), exposure gain, optics blur, then sensor noise."""
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise DatasetError(f"restyle takes (H, W) or (H, W, 3) uint8 images, got {image.shape} {image.dtype}")
    x = image.astype(np.float32) / 255.0
    x = x ** np.float32(style["gamma"])
    if x.ndim == 3:
        x = x * np.asarray(style["tint"], np.float32)[: x.shape[2]]
    x = x * np.float32(style["gain"])
    if style["blur_px"] > 0.2:
        x = cv2.GaussianBlur(x, (0, 0), float(style["blur_px"]))
    if style["noise"] > 0:
        x = x + rng.normal(0.0, style["noise"], size=x.shape).astype(np.float32)
    return (np.clip(x, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def _frame_files(folder: Path, name: str) -> list[Path]:
    return sorted(p for p in folder.glob(f"{name}.*") if p.is_file())


def select_copy_labels(src: Path, dst: Path, what: str, *, split: str | None = None, limit: int | None = None,
                       force: bool = False) -> list[dict[str, Any]]:
    """The ``labels.jsonl`` lines of dataset ``src`` (of ``split``, the first ``limit``) that a copy of it
    in ``dst`` is made from (by this module, or ``what`` else: derectify); ``dst`` is emptied with ``force``.

    Raises:
        DatasetError: ``src`` is not a dataset, ``dst`` is ``src`` or exists without ``force``, or no frame
            is selected.
    """
    labels_path = src / "labels.jsonl"
    if not labels_path.is_file() or not (src / "rig.yaml").is_file():
        raise DatasetError(f"{src} is not a dataset (needs labels.jsonl and rig.yaml)")
    if dst.resolve() == src.resolve():
        raise DatasetError(f"the {what} copy must not overwrite its source (DST must differ from SRC)")
    if dst.exists():
        if not force:
            raise DatasetError(f"{dst} exists; pass force=True (--force) to replace it")
        shutil.rmtree(dst)
    lines = [json.loads(line) for line in labels_path.read_text().splitlines() if line.strip()]
    if split is not None:
        lines = [line for line in lines if line.get("split", "train") == split]
    lines = lines[:limit] if limit is not None else lines
    if not lines:
        raise DatasetError(f"no {split or ''} frames to {what} in {src}".replace("  ", " "))
    return lines


def restyle_dataset(src: Path, dst: Path, seed: int, *, split: str | None = None, limit: int | None = None,
                    force: bool = False) -> int:
    """Write the restyled copy of ``src`` (its ``split`` frames, at most ``limit``) to ``dst``; returns
    the number of frames written.

    Raises:
        DatasetError: ``src`` is not a dataset, ``dst`` is ``src`` or exists without ``force``, or no frame
            is selected.
    """
    src, dst = Path(src), Path(dst)
    lines = select_copy_labels(src, dst, "restyle", split=split, limit=limit, force=force)
    rng = np.random.default_rng(seed)
    others = [p for p in sorted(src.iterdir()) if p.is_dir() and p.name not in VIEWS]
    for sub in (*VIEWS, *(p.name for p in others)):
        (dst / sub).mkdir(parents=True, exist_ok=True)
    out = []
    for line in lines:
        name = line["frame"]
        sources = {view: _frame_files(src / view, name) for view in VIEWS}
        if not all(sources.values()):
            raise DatasetError(f"frame {name} lacks a view in {src}")
        first = read_image(sources["left"][0])
        style = sample_style(rng, int(first.shape[1]))
        for view in VIEWS:
            image = first if view == "left" else read_image(sources[view][0])
            write_image(dst / view / sources[view][0].name, apply_style(image, style, rng))
        for folder in others:
            for path in _frame_files(folder, name):
                shutil.copy2(path, dst / folder.name / path.name)
        out.append({**line, "restyle": style})
    shutil.copy2(src / "rig.yaml", dst / "rig.yaml")
    meta = json.loads((src / "dataset.json").read_text()) if (src / "dataset.json").is_file() else {}
    meta.update({"count": len(out), "restyled_from": {"dataset": str(src), "seed": seed, "split": split,
                                                      "limit": limit}})
    (dst / "dataset.json").write_text(json.dumps(meta, indent=1) + "\n")
    (dst / "labels.jsonl").write_text("".join(json.dumps(line) + "\n" for line in out))
    log.info("restyled %d frames of %s into %s", len(out), src, dst)
    return len(out)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.restyle", description=__doc__.split("\n\n")[0])
    p.add_argument("src", type=Path)
    p.add_argument("dst", type=Path)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--split", choices=("train", "test"), default=None)
    p.add_argument("--limit", type=int, default=None)
    p.add_argument("--force", action="store_true", help="replace an existing DST")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        n = restyle_dataset(args.src, args.dst, args.seed, split=args.split, limit=args.limit, force=args.force)
    except DatasetError as exc:
        raise SystemExit(f"error: {exc}") from exc
    log.info("%d frames written", n)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
