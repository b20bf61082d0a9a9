"""Tests of spacepose.tools.outline_data, spacepose.tools.train_outline and spacepose.export.onnx_outline."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "runtime"))  # the runtime tests' bundle helpers

from spacepose.cli import main  # noqa: E402
from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.tools.outline_data import KEYS, PAD, load_outline_samples, make_outline_samples  # noqa: E402


def _samples(n=12, seed=0):
    """Outline samples of discs whose stereo outline also fills a notch the truth has (what the refiner learns)."""
    rng = np.random.default_rng(seed)
    out = {k: [] for k in KEYS}
    yy, xx = np.mgrid[0:PAD, 0:PAD]
    for i in range(n):
        size = int(rng.choice([64, 100, 150]))
        cx, cy, r = size / 2, size / 2, size / 3
        truth = ((xx - cx) ** 2 + (yy - cy) ** 2 < r * r) & (xx < size) & (yy < size)
        truth &= ~((np.abs(yy - cy) < size / 12) & (xx > cx))       # a notch, dark in the image
        observed = ((xx - cx) ** 2 + (yy - cy) ** 2 < (r + 2) ** 2) & (xx < size) & (yy < size)
        grey = np.where(truth, rng.uniform(0.3, 0.8, (PAD, PAD)), 0.01)
        out["grey"].append(grey.astype(np.float16))
        out["disp"].append(np.where(observed, 1.3, 0.2).astype(np.float16))
        out["observed"].append(observed.astype(np.uint8))
        out["truth"].append(truth.astype(np.uint8))
        out["size"].append(size)
        out["frame"].append(f"{i:06d}")
        out["regime"].append("sun")
        out["distance"].append(20.0)
        out["valid"].append(True)
    return {k: np.asarray(v) for k, v in out.items()}


def test_sample_files_load_and_refuse_others(tmp_path):
    s = _samples(4)
    np.savez_compressed(tmp_path / "a.npz", **s)
    np.savez_compressed(tmp_path / "b.npz", **_samples(3, seed=1))
    both = load_outline_samples([tmp_path / "a.npz", tmp_path / "b.npz"])
    assert len(both["size"]) == 7 and both["grey"].shape == (7, PAD, PAD)
    np.testing.assert_array_equal(both["truth"][:4], s["truth"])
    np.savez_compressed(tmp_path / "bad.npz", x=np.zeros(3))
    with pytest.raises(SpaceposeError, match="not an outline sample file"):
        load_outline_samples([tmp_path / "bad.npz"])


def test_samples_come_from_the_outline_decision_of_each_frame(tmp_path):
    """The tiny silhouette bundle of the runtime tests on a one-frame dataset of its synthetic pair."""
    from _bundle_fixtures import synthetic_pair
    from test_silhouette import _estimator

    from spacepose.calibration.rig import paper_rig, save_rig
    from spacepose.imageio import write_image

    est = _estimator(tmp_path, {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0})
    root = tmp_path / "ds"
    for sub in ("left", "right", "mask"):
        (root / sub).mkdir(parents=True)
    save_rig(paper_rig(640, 480), root / "rig.yaml")
    left, right = synthetic_pair()
    write_image(root / "left" / "000000.png", left)
    write_image(root / "right" / "000000.png", right)
    write_image(root / "mask" / "000000.png", ((left[..., 0] > 0) * 255).astype(np.uint8))
    (root / "labels.jsonl").write_text(json.dumps({
        "frame": "000000", "split": "train", "R": np.eye(3).tolist(), "t": [0.0, 0.0, 9.0],
        "q_wxyz": [1.0, 0.0, 0.0, 0.0], "regime": "sun", "degradations": {}, "sun_dir": [0.0, 0.0, 1.0]}) + "\n")
    s = make_outline_samples(root, "train", 0, 5, est.bundle.path)
    assert len(s["size"]) == 1 and s["frame"][0] == "000000" and bool(s["valid"][0])
    n = int(s["size"][0])
    obs, truth = s["observed"][0][:n, :n] > 0, s["truth"][0][:n, :n] > 0
    assert obs.sum() > 100 and truth.sum() > 100
    assert (obs & truth).sum() / (obs | truth).sum() > 0.8          # the stereo outline of the rectangle is near it
    assert not s["observed"][0][n:].any() and not s["grey"][0][:, n:].any()   # zero padding
    np.testing.assert_array_equal(s["disp"][0][:n, :n].astype(np.float32) > 1.0, obs)
    (root / "mask" / "000000.png").unlink()
    (root / "mask").rmdir()
    with pytest.raises(SpaceposeError, match="mask"):
        make_outline_samples(root, "train", 0, 5, est.bundle.path)


def test_training_lowers_the_chamfer_resumes_and_exports(tmp_path):
    np.savez_compressed(tmp_path / "train.npz", **_samples(16))
    np.savez_compressed(tmp_path / "val.npz", **_samples(6, seed=2))
    out = tmp_path / "run"
    args = ["train-outline", str(tmp_path / "train.npz"), "--val", str(tmp_path / "val.npz"), "--out", str(out),
            "--steps", "60", "--batch", "4", "--crop", "48", "--width", "8", "--val-every", "30", "--ckpt-every",
            "20", "--lr", "1e-2", "--threads", "1"]
    assert main(args) == 0
    vals = [json.loads(line)["val"] for line in (out / "log.jsonl").read_text().splitlines() if "val" in line]
    assert len(vals) == 2 and vals[-1]["n"] == 6
    assert vals[-1]["chamfer_refined"] < vals[-1]["chamfer_stereo"]       # it learns the notch
    assert main(args) != 0                                                  # last.pt exists: not overwritten
    ckpt = torch.load(out / "last.pt", weights_only=False)
    assert ckpt["kind"] == "outline" and ckpt["step"] == 60
    assert main([*args[:-8], "--steps", "80", "--val-every", "30", "--ckpt-every", "20", "--lr", "1e-2",
                 "--threads", "1", "--resume"]) == 0
    assert torch.load(out / "last.pt", weights_only=False)["step"] == 80

    # export: the graph reproduces the network on any frame size, and the bundle's section is written
    from spacepose.models.outline_refiner import OutlineRefinerConfig, OutlineRefinerNet
    from spacepose.outline_refiner import OutlineRefiner, OutlineRefinerConfig as Section
    from spacepose.tools.train_outline import frame_logits

    bundle = tmp_path / "bundle"
    bundle.mkdir()
    (bundle / "bundle.json").write_text(json.dumps({"outline_refiner": {"grow_px": 3}}))
    assert main(["export-outline", str(out / "last.pt"), "--out", str(bundle / "outline.onnx")]) == 0
    assert json.loads((bundle / "bundle.json").read_text())["outline_refiner"] == {"grow_px": 3,
                                                                                   "file": "outline.onnx"}
    assert main(["export-outline", str(out / "last.pt"), "--out", str(bundle / "outline.onnx")]) != 0   # exists
    net = OutlineRefinerNet(OutlineRefinerConfig(width=8))
    net.load_state_dict(torch.load(out / "last.pt", weights_only=False)["model"])
    net.eval()
    graph = OutlineRefiner(bundle, Section(grow_px=3), "tdrs")
    rng = np.random.default_rng(5)
    for n in (37, 64):
        planes = rng.uniform(0.0, 2.0, (3, n, n)).astype(np.float32)
        planes[1] = planes[1] > 1.0
        np.testing.assert_allclose(graph.logits(planes), frame_logits(net, planes), atol=1e-3)
