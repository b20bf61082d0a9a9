"""Tests of spacepose.photometric: left-right patch consistency of a pose against the images."""

import numpy as np
import pytest

from spacepose.photometric import photometric_consistency, to_grey_float

F, CX, CY, B = 800.0, 320.0, 240.0, 1.0
K = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
SIZE = (640, 480)


def _plane_surface(half=2.0, step=0.05):
    g = np.arange(-half, half + 1e-9, step)
    x, y = np.meshgrid(g, g)
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


def _render_plane(z, texture, half=2.0, x_cam=0.0):
    """Rectified left/right views of the square |x|,|y| <= half (object frame) facing the camera at depth z,
    textured by ``texture(x, y)``; black sky elsewhere."""
    w, h = SIZE
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    out = []
    for cam_x in (0.0, B):  # the right camera sits at +B
        X = (u - CX) * z / F + cam_x - x_cam
        Y = (v - CY) * z / F
        inside = (np.abs(X) <= half) & (np.abs(Y) <= half)
        img = np.where(inside, texture(X, Y), 0.0)
        out.append(np.clip(img, 0, 255).astype(np.uint8))
    return out


def _speckle(X, Y):
    # deterministic fine texture in object coordinates (visible at 20 m: ~2.5 px per 6 cm)
    return 110 + 60 * np.sin(37 * X + 3 * np.sin(11 * Y)) * np.cos(29 * Y + 2 * np.cos(13 * X))


def test_true_pose_scores_high_and_wrong_depths_low():
    z = 20.0
    left, right = _render_plane(z, _speckle)
    surface = _plane_surface()
    R = np.eye(3)
    true = photometric_consistency(R, np.array([0, 0, z]), surface, left, right, K, B)
    assert true.score is not None and true.score > 0.9 and true.patches > 100
    for scale in (0.9, 1.1, 1.2):
        wrong = photometric_consistency(R, np.array([0, 0, z * scale]), surface, left, right, K, B)
        assert wrong.score is not None and wrong.score < 0.5, (scale, wrong)


def test_smooth_gradients_are_not_evidence():
    # a horizontal ramp matches itself at every shift: it must not vouch for any depth
    left, right = _render_plane(20.0, lambda X, Y: 60 + 20 * X)
    res = photometric_consistency(np.eye(3), np.array([0, 0, 24.0]), _plane_surface(), left, right, K, B)
    assert res.score is None and res.visible > 0


def test_dark_view_is_unverifiable_and_off_image_pose_is_empty():
    black = np.zeros((480, 640), np.uint8)
    res = photometric_consistency(np.eye(3), np.array([0, 0, 20.0]), _plane_surface(), black, black, K, B)
    assert res.score is None and res.patches == 0
    behind = photometric_consistency(np.eye(3), np.array([0, 0, -20.0]), _plane_surface(), black, black, K, B)
    assert behind == type(behind)(None, 0, 0)


def test_nan_pose_and_shape_errors():
    img = np.zeros((480, 640), np.uint8)
    res = photometric_consistency(np.full((3, 3), np.nan), np.zeros(3), _plane_surface(), img, img, K, B)
    assert res.score is None
    with pytest.raises(ValueError):
        photometric_consistency(np.eye(3), np.zeros(3), _plane_surface(), img, img[:10], K, B)
    with pytest.raises(Exception):
        photometric_consistency(np.eye(3), np.zeros(2), _plane_surface(), img, img, K, B)


def test_grey_scales():
    assert to_grey_float(np.full((2, 2), 65535, np.uint16)).max() == pytest.approx(1.0)
    assert to_grey_float(np.full((2, 2, 3), 255, np.uint8)).max() == pytest.approx(1.0)
    assert to_grey_float(np.full((2, 2), 127.5, np.float32)).max() == pytest.approx(0.5)


def test_score_does_not_depend_on_the_frame_around_the_target():
    """Only the box the patches sample is read: a bigger canvas (shifted principal point) scores the same."""
    z = 20.0
    left, right = _render_plane(z, _speckle)
    surface = _plane_surface()
    t = np.array([0.0, 0.0, z])
    base = photometric_consistency(np.eye(3), t, surface, np.dstack([left] * 3), np.dstack([right] * 3), K, B)
    pad = ((37, 53), (81, 29), (0, 0))
    big_l, big_r = np.pad(np.dstack([left] * 3), pad), np.pad(np.dstack([right] * 3), pad)
    K_big = K.copy()
    K_big[0, 2] += 81
    K_big[1, 2] += 37
    big = photometric_consistency(np.eye(3), t, surface, big_l, big_r, K_big, B)
    assert (big.patches, big.visible) == (base.patches, base.visible)
    assert big.score == pytest.approx(base.score, abs=1e-5)
