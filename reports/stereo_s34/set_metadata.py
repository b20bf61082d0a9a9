"""Correct the metadata of the stereo graph shipped in session 34 (session 19's GPU-trained graph), weights untouched.

    python reports/stereo_s34/set_metadata.py runtime/bundles/default/stereo.onnx STEREO_EVAL_JSON

The device job of session 19 recorded the training seed (0) and the oversampled sample list (6,268) as the dataset,
and no metrics (the card, "Training on a lent accelerator"). This writes the rendered set's seed and sizes and the
test-split metrics of ``spacepose eval-stereo`` (its ``ours.overall``) into the graph's ``spacepose`` metadata, and
checks that every initializer is unchanged. Training side (needs ``onnx``).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import numpy_helper

METRIC_KEYS = ("epe", "rmse", "bad1", "bad3", "d1", "pixels", "frames", "density")


def main(argv: list[str]) -> int:
    graph_path, eval_path = Path(argv[0]), Path(argv[1])
    model = onnx.load(str(graph_path))
    before = {t.name: numpy_helper.to_array(t) for t in model.graph.initializer}
    props = {p.key: p for p in model.metadata_props}
    meta = json.loads(props["spacepose"].value)
    overall = json.loads(eval_path.read_text())["ours"]["overall"]
    meta["dataset"] = {"path": "/tmp/job/data (the device machine, session 19)", "seed": 11, "size": 4000,
                       "train_frames": 3600, "samples_per_epoch": 6268}
    meta["metrics"] = {k: overall[k] for k in METRIC_KEYS if k in overall}
    meta["metadata_note"] = ("dataset and metrics written in session 34 (reports/stereo_s34/set_metadata.py); "
                             "training_commit is the HEAD the device copy reported, its tree was 0a596dd")
    props["spacepose"].value = json.dumps(meta, sort_keys=True)
    onnx.save(model, str(graph_path))
    after = {t.name: numpy_helper.to_array(t) for t in onnx.load(str(graph_path)).graph.initializer}
    assert before.keys() == after.keys() and all(np.array_equal(before[k], after[k]) for k in before)
    print(json.dumps(meta["metrics"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
