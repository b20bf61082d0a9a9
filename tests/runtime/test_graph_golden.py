"""The shipped graphs against outputs stored from an earlier machine (cross-machine reproducibility).

Session 29 found 1-2 % of frames changing their validity when the same sets were rendered and evaluated on
another machine, without knowing whether the renderer or onnxruntime moved; the renderer has its own golden
test (``tests/tools/test_render_golden.py``). Here the default bundle's stereo, pose and flip graphs run, as
the runtime runs them (:func:`spacepose.onnx_session.make_session`, one thread, the memory arena on), on
fixed inputs made from a stored 160x120 frame, and must give the stored outputs back within 1e-3 (the
export parity bar). Whether they did so bit for bit shows in the summary line: ``test_bit_identical`` is an
expected failure that passes (xpassed) when they did. The inputs need neither the renderer nor torch.

Regenerate the file only when a graph of the default bundle changes::

    python tests/runtime/test_graph_golden.py --write
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

GOLDEN = Path(__file__).with_name("data") / "graph_golden.npz"
FRAME = Path(__file__).parents[1] / "tools" / "data" / "render_golden.npz"
FOCAL_PX, BASELINE_M = 200.0, 1.0   # the paper rig at 160x120 (the frame's rig)
ATOL = 1e-3


def _session(path: Path):
    from spacepose.onnx_session import make_session

    return make_session(path, threads=1, mem_arena=True)


def _stereo_inputs(frame: dict[str, np.ndarray], size: tuple[int, int]) -> dict[str, np.ndarray]:
    """The frame's target window (its mask's box, squared, 1.25x) resized to the graph's input, as the fine pass."""
    from spacepose import roi
    from spacepose.stereo_stage import to_net_input

    mask, disp = frame["mask0"], frame["disparity0"]
    box = roi.bbox_from_mask(mask)
    window = roi.square_window(box, float(disp[mask].min()), float(disp[mask].max()))
    left, _ = roi.crop_resize(frame["left0"], window, size)
    right, _ = roi.crop_resize(frame["right0"], window, size)
    return {"left": to_net_input(left), "right": to_net_input(right)}


def _pose_inputs(frame: dict[str, np.ndarray], spec) -> dict[str, np.ndarray]:
    """The frame's target pixels (with replacement, fixed seed) back-projected through the true disparity."""
    from spacepose.pose_inputs import build_pose_inputs

    mask, disp, left = frame["mask0"], frame["disparity0"], frame["left0"]
    h, w = mask.shape
    v, u = np.nonzero(mask)
    pick = np.random.default_rng(7).choice(len(u), spec.n_points, replace=len(u) < spec.n_points)
    u, v = u[pick], v[pick]
    z = FOCAL_PX * BASELINE_M / disp[v, u].astype(np.float64)
    xyz = np.stack([(u - (w - 1) / 2) * z / FOCAL_PX, (v - (h - 1) / 2) * z / FOCAL_PX, z], axis=1)
    cw, ch = spec.crop_size
    crop = cv2.resize(left, (cw, ch), interpolation=cv2.INTER_AREA)
    pixels = np.stack([u * cw // w, v * ch // h], axis=1).astype(np.int64)
    inputs, _ = build_pose_inputs(crop, xyz, pixels, spec)
    return inputs


def _flip_inputs(frame: dict[str, np.ndarray], bundle) -> np.ndarray:
    """The views of the frame's true pose against its flip, and of the flip against the true pose."""
    from spacepose import roi
    from spacepose.flip import flipped_pose
    from spacepose.flip_views import flip_views

    h, w = frame["mask0"].shape
    K = np.array([[FOCAL_PX, 0.0, (w - 1) / 2], [0.0, FOCAL_PX, (h - 1) / 2], [0.0, 0.0, 1.0]])
    x0, y0, x1, y1 = roi.bbox_from_mask(frame["mask0"])
    side = int(1.25 * max(x1 - x0, y1 - y0))
    window = ((x0 + x1 - side) // 2, (y0 + y1 - side) // 2, side)
    pose = (frame["R0"], frame["t0"])
    flip = flipped_pose(*pose, np.asarray(bundle.centre), bundle.flip_classifier.axis)
    points = np.asarray(bundle.silhouette_points, dtype=np.float32)
    size = bundle.flip_classifier.size
    return np.stack([flip_views(frame["left0"], K, window, points, pose, flip, size),
                     flip_views(frame["left0"], K, window, points, flip, pose, size)])


def run_graphs() -> dict[str, np.ndarray]:
    """The default bundle's graph outputs on the fixed inputs (subsampled where large)."""
    from spacepose.bundle import load_bundle

    bundle = load_bundle()
    with np.load(FRAME) as stored:
        frame = dict(stored)
    stereo = _session(bundle.stereo_path)
    size = tuple(stereo.get_inputs()[0].shape[3:1:-1])
    (disparity,) = stereo.run(["disparity"], _stereo_inputs(frame, size))
    pose = _session(bundle.pose_path)
    seg, kp, ctr = pose.run(["seg_logits", "kp_offsets", "ctr_offsets"], _pose_inputs(frame, bundle.pose.input_spec))
    out = {"disparity": disparity[0, 0, ::4, ::4], "seg_logits": seg[0], "kp_offsets": kp[0, :, ::8],
           "ctr_offsets": ctr[0]}
    if bundle.flip_classifier is not None:
        flip = _session(bundle.path / bundle.flip_classifier.file)
        (logit,) = flip.run(["logit"], {"views": _flip_inputs(frame, bundle)})
        out["flip_logit"] = logit
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in out.items()}


@pytest.fixture(scope="module")
def outputs():
    if not GOLDEN.exists():
        pytest.fail(f"{GOLDEN} is missing: run `python {Path(__file__).name} --write` after a graph change")
    with np.load(GOLDEN) as stored:
        return dict(stored), run_graphs()


def test_same_outputs(outputs):
    stored, now = outputs
    assert sorted(stored) == sorted(now)
    for key in stored:
        assert stored[key].shape == now[key].shape, key


def test_inputs_are_not_trivial(outputs):
    """Outputs that do not vary would test little: a target's disparity spans pixels, the logits differ."""
    stored, _ = outputs
    assert np.ptp(stored["disparity"]) > 1.0
    assert np.ptp(stored["ctr_offsets"]) > 0.1
    if "flip_logit" in stored:   # the same two poses in the other order: the graph is antisymmetric
        np.testing.assert_allclose(stored["flip_logit"][0], -stored["flip_logit"][1], atol=1e-4)


@pytest.mark.parametrize("key", ["disparity", "seg_logits", "kp_offsets", "ctr_offsets", "flip_logit"])
def test_matches_stored(outputs, key):
    stored, now = outputs
    if key not in stored:
        pytest.skip(f"the default bundle has no {key}")
    np.testing.assert_allclose(now[key], stored[key], rtol=0, atol=ATOL, err_msg=key)


@pytest.mark.xfail(strict=False, reason="onnxruntime's kernels for another instruction set may round differently; "
                   "the summary's xpassed / xfailed count tells whether this machine gives the graphs bit for bit")
def test_bit_identical(outputs):
    stored, now = outputs
    for key, value in stored.items():
        np.testing.assert_array_equal(now[key], value, err_msg=key)


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        raise SystemExit(f"usage: python {sys.argv[0]} --write   (overwrites {GOLDEN})")
    GOLDEN.parent.mkdir(exist_ok=True)
    np.savez_compressed(GOLDEN, **run_graphs())
    print(f"wrote {GOLDEN} ({GOLDEN.stat().st_size / 1024:.0f} KiB)")
