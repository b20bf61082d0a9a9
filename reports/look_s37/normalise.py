"""Session 37: does normalising the input images at run time undo another look? Measured, not shipped.

    python reports/look_s37/normalise.py copy SRC DST {grey,wb} N     # the first N test frames of SRC, normalised
    python reports/look_s37/normalise.py table RUNS                   # EPE / D1 table from the eval-stereo runs

``grey``: luminance (0.299 R + 0.587 G + 0.114 B) in all three channels; ``wb``: grey-world white balance, one gain
per channel from the mean of both views' lit pixels (any channel > 8), so that the three means agree. The same
transform goes to both views; disparity, masks and labels are copied unchanged. The runs, on the first 150 test
frames (the frames of session 36's table):

    python reports/look_s37/normalise.py copy data/tdrs640 /tmp/s37/d_plain_grey grey 150    (and wb; and
        data/tdrs640_restyle -> /tmp/s37/d_rest_{grey,wb})
    spacepose eval-stereo /tmp/s37/d_{plain,rest}_{grey,wb} --limit 150 --threads 1 --out RUNS/{plain,rest}_{grey,wb}

``table`` reads those four and session 36's ``runs/st36_shipped_{plain,rest}`` (the images as they are).
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from spacepose.imageio import read_image, write_image

LUMA = np.array([0.299, 0.587, 0.114], np.float32)


def grey(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    def one(x: np.ndarray) -> np.ndarray:
        y = (x.astype(np.float32) @ LUMA + 0.5).clip(0, 255).astype(np.uint8)
        return np.repeat(y[..., None], 3, axis=2)
    return one(left), one(right)


def white_balance(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    both = np.concatenate([left.reshape(-1, 3), right.reshape(-1, 3)]).astype(np.float64)
    lit = both[both.max(axis=1) > 8]
    mean = lit.mean(axis=0) if len(lit) > 100 else np.ones(3)
    gain = (mean.mean() / np.maximum(mean, 1e-3)).astype(np.float32)
    return tuple((x.astype(np.float32) * gain + 0.5).clip(0, 255).astype(np.uint8) for x in (left, right))


def copy(src: Path, dst: Path, kind: str, n: int) -> int:
    fn = {"grey": grey, "wb": white_balance}[kind]
    lines = [json.loads(x) for x in (src / "labels.jsonl").read_text().splitlines() if x.strip()]
    lines = [x for x in lines if x.get("split", "train") == "test"][:n]
    subs = [p for p in src.iterdir() if p.is_dir()]
    for sub in subs:
        (dst / sub.name).mkdir(parents=True, exist_ok=True)
    for line in lines:
        name = line["frame"]
        files = {v: sorted((src / v).glob(name + ".*"))[0] for v in ("left", "right")}
        left, right = fn(read_image(files["left"]), read_image(files["right"]))
        write_image(dst / "left" / files["left"].name, left)
        write_image(dst / "right" / files["right"].name, right)
        for sub in subs:
            if sub.name not in ("left", "right"):
                for p in sub.glob(name + ".*"):
                    shutil.copy2(p, dst / sub.name / p.name)
    for f in ("rig.yaml", "dataset.json"):
        if (src / f).is_file():
            shutil.copy2(src / f, dst / f)
    (dst / "labels.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return len(lines)


def table(runs: Path) -> None:
    cols = {"as is, plain": Path("runs/st36_shipped_plain"), "as is, restyled": Path("runs/st36_shipped_rest"),
            "grey, plain": runs / "plain_grey", "wb, plain": runs / "plain_wb",
            "grey, restyled": runs / "rest_grey", "wb, restyled": runs / "rest_wb"}
    docs = {k: json.loads((v / "stereo_eval.json").read_text()) for k, v in cols.items()}
    print("EPE px / D1 %, the shipped stereo graph, first 150 test frames\n")
    print("| group | " + " | ".join(docs) + " |\n|---|" + "---|" * len(docs))
    for group in docs["as is, plain"]["ours"]:
        print(f"| {group} | " + " | ".join(f"{d['ours'][group]['epe']:.3f} / {d['ours'][group]['d1']:.2f}"
                                         for d in docs.values()) + " |")


if __name__ == "__main__":
    if sys.argv[1] == "copy":
        print(copy(Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[4], int(sys.argv[5])))
    else:
        table(Path(sys.argv[2]))
