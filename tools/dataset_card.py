"""Dataset card: distributions of a rendered dataset, the paper's Fig. 11/12 plots and contact sheets.

Reads only the CONVENTIONS layout (``labels.jsonl``, ``left/``), so it works on any dataset folder.
"""

from __future__ import annotations

import logging
from collections import Counter
from pathlib import Path

import numpy as np

from spacepose.errors import DatasetError
from spacepose.imageio import read_image
from spacepose.tools.labels import FrameLabel
from spacepose.tools.labels import read_labels as _read_labels

log = logging.getLogger(__name__)

DISTANCE_BINS_M = (10.0, 20.0, 30.0, 40.0, 50.0)


def read_labels(dataset: Path) -> list[FrameLabel]:
    """Parse ``dataset/labels.jsonl`` (split, regime and pose required on every line); DatasetError on
    a missing file, a malformed line or no frames."""
    labels = _read_labels(dataset, require=("split", "regime", "R", "t"))
    if not labels:
        raise DatasetError(f"{Path(dataset) / 'labels.jsonl'} holds no frames")
    return labels


def summarise(labels: list[FrameLabel]) -> dict:
    """Counts per split, regime and degradation; distance histogram per split (JSON-ready)."""
    splits = sorted({lab.split for lab in labels})
    summary: dict = {"n_frames": len(labels), "splits": {}}
    for split in splits:
        sub = [lab for lab in labels if lab.split == split]
        z = np.array([lab.t[2] for lab in sub])
        hist, _ = np.histogram(z, bins=DISTANCE_BINS_M)
        degr = Counter(name for lab in sub for name in lab.degradations)
        summary["splits"][split] = {
            "n": len(sub),
            "regimes": dict(sorted(Counter(lab.regime for lab in sub).items())),
            "degradations": dict(sorted(degr.items())),
            "z_min": float(z.min()),
            "z_max": float(z.max()),
            "z_mean": float(z.mean()),
            "z_hist_bins_m": list(DISTANCE_BINS_M),
            "z_hist": hist.tolist(),
        }
    return summary


def format_summary(summary: dict) -> str:
    """Plain-text table of :func:`summarise`'s output."""
    lines = [f"frames: {summary['n_frames']}"]
    for split, s in summary["splits"].items():
        lines.append(f"[{split}] n={s['n']}  z: {s['z_min']:.1f}..{s['z_max']:.1f} m (mean {s['z_mean']:.1f})")
        lines.append("  regimes:      " + "  ".join(f"{k}={v}" for k, v in s["regimes"].items()))
        lines.append("  degradations: " + "  ".join(f"{k}={v}" for k, v in s["degradations"].items()))
        bins = s["z_hist_bins_m"]
        lines.append(
            "  distance:     "
            + "  ".join(f"{bins[i]:.0f}-{bins[i + 1]:.0f}m={n}" for i, n in enumerate(s["z_hist"]))
        )
    return "\n".join(lines)


def plot_distributions(labels: list[FrameLabel], out_dir: Path) -> list[Path]:
    """Write fig11_distance.png (target distance per split) and fig12_camera_positions.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    colours = {"train": "tab:blue", "test": "tab:orange"}
    written = []

    fig, ax = plt.subplots(figsize=(7, 4))
    for split in sorted({lab.split for lab in labels}):
        sub = [lab for lab in labels if lab.split == split]
        ax.scatter(np.arange(len(sub)), [lab.t[2] for lab in sub], s=4, label=split, c=colours.get(split))
    ax.set_xlabel("sample index within split")
    ax.set_ylabel("target distance $Z_c$ [m]")
    ax.set_title("Target distance per split (cf. paper Fig. 11)")
    ax.legend()
    fig.tight_layout()
    written.append(out_dir / "fig11_distance.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    for split in sorted({lab.split for lab in labels}):
        cams = np.array([lab.camera_in_body for lab in labels if lab.split == split])
        axes[0].scatter(cams[:, 0], cams[:, 1], s=3, label=split, c=colours.get(split), alpha=0.6)
        axes[1].scatter(cams[:, 0], cams[:, 2], s=3, label=split, c=colours.get(split), alpha=0.6)
    for ax, (a, b) in zip(axes, [("x_B", "y_B"), ("x_B", "z_B")]):
        ax.set_xlabel(f"${a}$ [m]")
        ax.set_ylabel(f"${b}$ [m]")
        ax.set_aspect("equal")
        ax.legend()
    fig.suptitle("Camera positions in the target body frame (cf. paper Fig. 12)")
    fig.tight_layout()
    written.append(out_dir / "fig12_camera_positions.png")
    fig.savefig(written[-1], dpi=110)
    plt.close(fig)
    return written


def contact_sheets(dataset: Path, labels: list[FrameLabel], out_dir: Path, per_regime: int = 8,
                   thumb: tuple[int, int] = (240, 180)) -> list[Path]:
    """One PNG per regime: ``per_regime`` left images (with distance captions) in a grid."""
    import cv2

    from spacepose.imageio import write_image

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for regime in sorted({lab.regime for lab in labels}):
        sub = [lab for lab in labels if lab.regime == regime][:per_regime]
        tiles = []
        for lab in sub:
            path = Path(dataset) / "left" / f"{lab.frame}.png"
            try:
                img = read_image(path)
            except Exception as err:  # a missing frame must not stop the card
                log.warning("contact sheet: %s", err)
                continue
            if img.ndim == 2:
                img = np.repeat(img[..., None], 3, axis=2)
            if img.dtype != np.uint8:
                img = (img / 257).astype(np.uint8)
            tile = cv2.resize(img, thumb, interpolation=cv2.INTER_AREA)
            cv2.putText(tile, f"{lab.frame} z={lab.t[2]:.0f}m", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                        (255, 255, 0), 1, cv2.LINE_AA)
            tiles.append(tile)
        if not tiles:
            continue
        cols = 4
        rows = -(-len(tiles) // cols)
        sheet = np.zeros((rows * thumb[1], cols * thumb[0], 3), np.uint8)
        for i, tile in enumerate(tiles):
            r, c = divmod(i, cols)
            sheet[r * thumb[1]:(r + 1) * thumb[1], c * thumb[0]:(c + 1) * thumb[0]] = tile
        written.append(out_dir / f"contact_{regime}.png")
        write_image(written[-1], sheet)
    return written
