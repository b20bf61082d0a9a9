"""A tiny synthetic stereo dataset in the CONVENTIONS layout (textured fronto-parallel plates)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from spacepose.calibration.rig import paper_rig, save_rig
from spacepose.imageio import write_image, write_pfm

REGIMES = ("sun", "albedo", "penumbra", "mixed")
SIZE = (160, 128)  # (w, h): small so tests are fast; the code is size-agnostic


def make_synthetic_dataset(root: Path, n_train: int = 6, n_test: int = 4, seed: int = 0) -> Path:
    """Textured rectangular plates at constant integer disparity on a black sky with dim stars."""
    rng = np.random.default_rng(seed)
    w, h = SIZE
    for sub in ("left", "right", "disparity", "mask"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    rig = paper_rig(w, h)
    save_rig(rig, root / "rig.yaml")
    focal = float(rig.M1[0, 0])
    lines = []
    for i in range(n_train + n_test):
        name = f"{i:06d}"
        z = 10.0 + 40.0 * (i + 0.5) / (n_train + n_test)
        d = max(3, int(round(focal * 1.0 / z)))  # paper rig: B = 1 m
        tex = rng.uniform(20, 235, size=(h // 2, w // 2)).astype(np.float32)
        tex = cv2.resize(tex, (w, h), interpolation=cv2.INTER_LINEAR)
        bw, bh = int(rng.integers(30, 60)), int(rng.integers(24, 50))
        x0 = int(rng.integers(d + 2, w - bw - 2))
        y0 = int(rng.integers(2, h - bh - 2))
        mask = np.zeros((h, w), bool)
        mask[y0:y0 + bh, x0:x0 + bw] = True
        left = np.where(mask, tex, 0.0)
        right = np.zeros_like(left)
        right[:, : w - d] = left[:, d:]  # x_right = x_left - d
        stars = rng.random((h, w)) < 0.002
        left = np.where(stars & ~mask, 180.0, left)
        right = np.where(stars & ~np.roll(mask, -d, axis=1), 180.0, right)
        disp = np.where(mask, float(d), 0.0).astype(np.float32)
        rgb = lambda a: np.repeat(np.clip(a, 0, 255).astype(np.uint8)[..., None], 3, axis=2)  # noqa: E731
        write_image(root / "left" / f"{name}.png", rgb(left))
        write_image(root / "right" / f"{name}.png", rgb(right))
        write_pfm(root / "disparity" / f"{name}.pfm", disp)
        write_image(root / "mask" / f"{name}.png", (mask * 255).astype(np.uint8))
        lines.append({"frame": name, "split": "train" if i < n_train else "test", "R": np.eye(3).tolist(),
                      "t": [0.0, 0.0, z], "q_wxyz": [1.0, 0.0, 0.0, 0.0], "regime": REGIMES[i % 4],
                      "degradations": {}, "sun_dir": [0.0, 0.0, 1.0]})
    (root / "labels.jsonl").write_text("".join(json.dumps(l) + "\n" for l in lines))
    return root


@pytest.fixture(scope="session")
def synthetic_dataset(tmp_path_factory) -> Path:
    return make_synthetic_dataset(tmp_path_factory.mktemp("stereo_ds"))


@pytest.fixture(scope="session")
def tiny_bundle(tmp_path_factory) -> Path:
    """A bundle folder with a random-init stereo graph (64x64, 2 iterations)."""
    pytest.importorskip("torch")
    from spacepose.export.onnx_stereo import export_random_stereo

    folder = tmp_path_factory.mktemp("bundle")
    export_random_stereo(folder / "stereo.onnx", size=(64, 64), iters=2)
    return folder
