"""Tests of spacepose.tools.derectify: raw frames of a distorted, turned rig from an ideal dataset.

A scene of bright dots at known 3D points is drawn by an ideal rig; derectified, each dot must sit
where OpenCV's camera model of the raw rig puts it (``cv2.projectPoints`` with its distortion), and
after the runtime's own rectification (``cv2.stereoRectify``) where the rewritten labels put it, on
the same row in both views.
"""

import json

import cv2
import numpy as np
import pytest

from spacepose.calibration.rectify import rectify
from spacepose.calibration.rig import load_rig, paper_rig, save_rig
from spacepose.errors import DatasetError
from spacepose.imageio import write_image
from spacepose.tools.derectify import RawRigConfig, derectify_dataset, main, sample_raw_rig

W, H = 320, 240
SIGMA = 1.6


def _dots(K, X_cam, shift_x=0.0):
    """(H, W) uint8 image with a Gaussian dot at each projection of X_cam (N, 3) (camera moved by shift_x)."""
    X = X_cam - np.array([shift_x, 0.0, 0.0])
    uv = (K @ (X / X[:, 2:3]).T).T[:, :2]
    v, u = np.mgrid[0:H, 0:W]
    img = np.zeros((H, W))
    for x, y in uv:
        img += np.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * SIGMA ** 2))
    return np.clip(img * 250.0, 0, 255).astype(np.uint8)


def _centroid(img, near, r=5):
    x0, y0 = int(round(near[0])), int(round(near[1]))
    patch = img[y0 - r:y0 + r + 1, x0 - r:x0 + r + 1].astype(np.float64)
    patch = np.maximum(patch - 0.2 * patch.max(), 0.0)
    v, u = np.mgrid[y0 - r:y0 + r + 1, x0 - r:x0 + r + 1]
    return np.array([(u * patch).sum(), (v * patch).sum()]) / patch.sum()


R_OBJ = cv2.Rodrigues(np.array([0.1, -0.2, 0.5]))[0]
T_OBJ = np.array([0.2, -0.1, 12.0])


@pytest.fixture()
def scene(tmp_path):
    ideal = paper_rig(W, H)
    K = np.asarray(ideal.M1)
    # dots over the middle of the view (the raw cameras turn by up to 2 deg: stay inside both)
    gx, gy = np.meshgrid(np.linspace(-1.6, 1.6, 5), np.linspace(-1.1, 1.1, 4))
    X_cam = np.stack([gx.ravel(), gy.ravel(), 12.0 + 0.3 * gx.ravel()], axis=1)
    X_obj = (X_cam - T_OBJ) @ R_OBJ    # R^T (X - t)
    src = tmp_path / "ideal"
    for sub in ("left", "right", "mask"):
        (src / sub).mkdir(parents=True)
    write_image(src / "left" / "000000.png", _dots(K, X_cam))
    write_image(src / "right" / "000000.png", _dots(K, X_cam, shift_x=float(-ideal.T[0])))
    write_image(src / "mask" / "000000.png", (_dots(K, X_cam) > 60).astype(np.uint8) * 255)
    save_rig(ideal, src / "rig.yaml")
    label = {"frame": "000000", "split": "test", "R": R_OBJ.tolist(), "t": T_OBJ.tolist(), "q_wxyz": [1, 0, 0, 0],
             "regime": "sun", "sun_dir": [0.0, 0.0, 1.0]}
    (src / "labels.jsonl").write_text(json.dumps(label) + "\n")
    return src, X_cam, X_obj


def test_dots_land_where_the_raw_rig_and_its_rectification_put_them(scene, tmp_path):
    src, X_cam, X_obj = scene
    dst = tmp_path / "raw"
    raw = derectify_dataset(src, dst, seed=3, config=RawRigConfig(rot_deg=2.0))
    rig = load_rig(dst / "rig.yaml")
    assert np.linalg.norm(cv2.Rodrigues(rig.R)[0]) > np.deg2rad(0.1) and abs(rig.D1[0]) > 1e-3  # not ideal
    left = cv2.imread(str(dst / "left" / "000000.png"), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(str(dst / "right" / "000000.png"), cv2.IMREAD_GRAYSCALE)
    # 1. raw images follow OpenCV's model of the raw cameras (distortion included)
    b = float(-raw.ideal.T[0])
    for img, Rc, M, D, Xc in ((left, raw.Rl, rig.M1, rig.D1, X_cam),
                              (right, raw.Rr, rig.M2, rig.D2, X_cam - np.array([b, 0.0, 0.0]))):
        expected, _ = cv2.projectPoints(Xc @ Rc.T, np.zeros(3), np.zeros(3), M, D)
        for p in expected[:, 0, :]:
            assert np.linalg.norm(_centroid(img, p) - p) < 0.3
    # 2. the runtime's rectification brings them back to one row, at the rewritten labels' pose
    rect = rectify(rig)
    left_r, right_r = rect.rectify_pair(left, right)
    label = json.loads((dst / "labels.jsonl").read_text())
    X_rect = X_obj @ np.asarray(label["R"]).T + np.asarray(label["t"])
    np.testing.assert_allclose(X_rect, X_cam @ raw.to_rect.T, atol=1e-9)
    uv = (rect.K @ (X_rect / X_rect[:, 2:3]).T).T[:, :2]
    d = rect.focal_px * rect.baseline_m / X_rect[:, 2]
    for p, disp in zip(uv, d):
        cl = _centroid(left_r, p)
        cr = _centroid(right_r, p - np.array([disp, 0.0]))
        assert np.linalg.norm(cl - p) < 0.4
        assert abs(cl[1] - cr[1]) < 0.3 and abs((cl[0] - cr[0]) - disp) < 0.4
    q = np.asarray(label["q_wxyz"])
    assert abs(np.linalg.norm(q) - 1.0) < 1e-9
    np.testing.assert_allclose(label["sun_dir"], raw.to_rect @ np.array([0.0, 0.0, 1.0]), atol=1e-12)
    assert cv2.imread(str(dst / "mask" / "000000.png"), cv2.IMREAD_GRAYSCALE).max() == 255


def test_refuses_to_overwrite_and_non_ideal_sources(scene, tmp_path):
    src, _, _ = scene
    dst = tmp_path / "raw"
    dst.mkdir()
    with pytest.raises(DatasetError, match="exists"):
        derectify_dataset(src, dst, seed=1)
    assert main([str(src), str(dst), "--seed", "1"]) == 2
    derectify_dataset(src, dst, seed=1, force=True)
    with pytest.raises(DatasetError, match="ideal parallel rig"):
        sample_raw_rig(load_rig(dst / "rig.yaml"), seed=1)
    with pytest.raises(DatasetError, match="differ"):
        derectify_dataset(src, src, seed=1, force=True)
    assert (src / "left" / "000000.png").is_file()   # the source is untouched


@pytest.mark.parametrize("kwargs", [{"rot_deg": -1.0}, {"focal_pct": float("nan")}, {"centre_pct": 90.0}])
def test_config_out_of_range(kwargs):
    with pytest.raises(ValueError):
        RawRigConfig(**kwargs)
