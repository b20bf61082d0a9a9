"""Session 38: does the flip classifier's decision hold under other tone curves? Exploration on spent frames.

    python reports/tone_s38/explore.py capture ROWS.json.gz DATASET OUT.npz   # views of the classifier's decisions
    python reports/tone_s38/explore.py table OUT.npz...                       # p under changed looks

``capture`` re-runs the shipped bundle (as ``spacepose eval-pose DATASET --split train``) on the frames that ``ROWS``
(session 37's committed check rows, ``reports/wide_s37/check*_base_*.json.gz``) say the classifier decided, and keeps
the classifier's view of each. ``table`` scores each view again with its grey plane changed (a tone curve: the power
g; a blur; saturation: clipped at a level and re-normalised) and counts the right and the wrong poses (off by > 20°
or > 0.5 m) whose decision would still hold at ``decide_prob`` 0.995. The session-38 run (the views are not kept):

    for s in check_base_plain:tdrs640_s37chk check_base_rest:tdrs640_s37chk_r check2_base_plain:tdrs640_s37chk2 \\
             check2_base_rest:tdrs640_s37chk2_r; do
        python reports/tone_s38/explore.py capture reports/wide_s37/${s%%:*}.json.gz data/${s##*:} /tmp/s38/cap_${s%%:*}.npz
    done
    python reports/tone_s38/explore.py table /tmp/s38/cap_*.npz      # -> explore_output.txt
"""
from __future__ import annotations

import gzip
import json
import sys

import numpy as np

DECIDE = 0.995


def capture(rows_path: str, dataset: str, out: str) -> None:
    import spacepose.flip_classifier as fcm
    import spacepose.tools.pose_data as pose_data
    from spacepose.tools.eval_pose import evaluate_pose

    want = {r["frame"] for r in json.load(gzip.open(rows_path, "rt"))["frames"]
            if r["valid"] and r["decided_by"] == "classifier"}
    read = pose_data.read_pose_labels
    pose_data.read_pose_labels = lambda root, split: [r for r in read(root, split) if r.frame in want]
    views, make = [], fcm.FlipClassifier.views

    def kept(self, *args):
        v = make(self, *args)
        views.append(v[0])
        return v

    fcm.FlipClassifier.views = kept
    rows = evaluate_pose(dataset, None, threads=1, split="train", overlays=0)["frames"]
    if len(views) != len(rows):
        raise SystemExit(f"{len(views)} views for {len(rows)} frames")
    np.savez_compressed(out, views=np.stack(views), frames=np.array([r["frame"] for r in rows]),
                        e_R=np.array([r["e_R"] for r in rows]), e_t=np.array([r["e_t"] for r in rows]),
                        valid=np.array([r["valid"] for r in rows]), route=np.array([r["decided_by"] for r in rows]))


def _changes() -> dict:
    import cv2

    def saturated(level: float):
        def change(v: np.ndarray) -> np.ndarray:
            g = np.minimum(v[0], level)
            union = (v[1] > 0) | (v[2] > 0)
            return g / max(float(np.percentile(g[union], 90)) if union.any() else 1.0, 1e-3)
        return change

    out = {f"g{p:g}": (lambda p: lambda v: np.clip(v[0], 0, 2) ** p)(p) for p in (0.5, 0.625, 1.6, 2.0)}
    out["blur1"] = lambda v: cv2.GaussianBlur(v[0], (0, 0), 1.0)
    out["sat0.7"], out["sat0.5"] = saturated(0.7), saturated(0.5)
    return out


def table(paths: list[str]) -> None:
    import onnxruntime as ort

    from spacepose.bundle import load_bundle

    session = ort.InferenceSession(str(load_bundle(None, verify_graphs=False).path / "flip.onnx"))

    def prob(v: np.ndarray) -> np.ndarray:
        return 1.0 / (1.0 + np.exp(-session.run(None, {"views": v.astype(np.float32)})[0].astype(np.float64)))

    changes, rows = _changes(), []
    for path in paths:
        d = np.load(path)
        views = d["views"]
        ps = {"p": prob(views)}
        for key, change in changes.items():
            w = views.copy()
            w[:, 0] = np.clip(np.stack([change(v) for v in views]), 0.0, 2.0)
            ps[key] = prob(w)
        for i in range(len(views)):
            side = ps["p"][i] >= 0.5                        # the support for the side the classifier decided
            rows.append({"set": path.rsplit("cap_", 1)[-1][:-4], "frame": str(d["frames"][i]),
                         "e_R": float(d["e_R"][i]), "e_t": float(d["e_t"][i]), "valid": bool(d["valid"][i]),
                         **{k: float(v[i] if side else 1.0 - v[i]) for k, v in ps.items()}})
    valid = [r for r in rows if r["valid"]]
    wrong = [r for r in valid if r["e_R"] > 20.0 or r["e_t"] > 0.5]
    right = [r for r in valid if r not in wrong]
    print(f"{len(rows)} frames, {len(valid)} valid again ({len(wrong)} wrong: > 20° or > 0.5 m)")
    for r in wrong:
        print(f"  {r['set']} {r['frame']}: {r['e_R']:.1f}° {r['e_t']:.2f} m",
              {k: round(r[k], 4) for k in ["p", *changes]})
    print(f"decision still at p >= {DECIDE}:    right kept / {len(right)}   wrong kept / {len(wrong)}")
    combos = [(k,) for k in changes] + [("g0.625", "g1.6"), ("g0.5", "g2"), ("g0.5", "g2", "blur1"),
                                        tuple(changes)]
    for combo in combos:
        def holds(r):
            return all(r[k] >= DECIDE for k in ("p", *combo))
        print(f"  {' + '.join(combo):45s} {sum(map(holds, right)):4d}   {sum(map(holds, wrong)):4d}")


if __name__ == "__main__":
    if sys.argv[1] == "capture":
        capture(*sys.argv[2:5])
    else:
        table(sys.argv[2:])
