"""Tests of spacepose.outline_search: directions, rotations, the grid homography, the global search."""

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from test_silhouette import K, _disparity_of, _slab  # noqa: E402

from spacepose.errors import ShapeError  # noqa: E402
from spacepose.flip import flipped_pose  # noqa: E402
from spacepose.outline_search import (OutlineTemplates, grid_homography, ray_rotation,  # noqa: E402
                                      search_outline, sphere_directions, view_rotation)
from spacepose.registration import rotation_angle_deg  # noqa: E402
from spacepose.silhouette import SilhouetteConfig, decide_outline, silhouette_frame, splat_mask  # noqa: E402


@pytest.fixture(scope="module")
def bracket():
    """An L of two slabs with a fin on one arm: no rotation maps its outline onto itself."""
    rng = np.random.default_rng(3)
    parts = [_slab((-2.0, -0.4, -0.3), (2.0, 0.4, 0.3), 1500, rng),
             _slab((1.2, 0.4, -0.3), (2.0, 2.4, 0.3), 1500, rng),
             _slab((-2.0, -0.1, 0.3), (-1.2, 0.1, 1.6), 1500, rng)]
    pts = np.vstack([p for p, _ in parts])
    return pts, pts.mean(axis=0), float(np.linalg.norm(pts - pts.mean(axis=0), axis=1).max())


@pytest.fixture(scope="module")
def templates(bracket):
    pts, centre, radius = bracket
    return OutlineTemplates(pts, centre, radius, views=1000, grid=32)


def test_sphere_directions_are_unit_and_spread():
    d = sphere_directions(2000)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert np.linalg.norm(d.mean(axis=0)) < 0.01                # no side favoured
    # every direction of a random sample has a grid direction within 5 degrees (spacing ~4.5 deg)
    probe = Rotation.random(200, random_state=0).apply([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(np.clip(probe @ d.T, -1, 1)).min(axis=1)).max() < 5.0
    with pytest.raises(ValueError):
        sphere_directions(0)


@pytest.mark.parametrize("w", [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0.3, -0.5, 0.8], [-0.95, 0.1, 0.2]])
def test_view_rotation_takes_the_direction_to_the_optical_axis(w):
    w = np.asarray(w, float) / np.linalg.norm(w)
    R = view_rotation(w)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ w, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(ray_rotation(w) @ [0, 0, 1], w, atol=1e-12)
    with pytest.raises(ShapeError):
        view_rotation(np.ones(2))


def test_grid_homography_matches_opencv_projection():
    ray = np.array([0.2, -0.1, 1.0])
    ray /= np.linalg.norm(ray)
    R_ray, angle, dist, cell, half = ray_rotation(ray), 0.7, 23.0, 0.2, 3.2
    H = grid_homography(K, R_ray, angle, dist, cell, half)
    cols, rows = np.meshgrid(np.arange(0, 32, 5.0), np.arange(0, 32, 7.0))
    g = np.stack([cols.ravel(), rows.ravel()], 1)
    metric = (g + 0.5) * cell - half
    c, s = np.cos(angle), np.sin(angle)
    X_virtual = np.column_stack([metric @ np.array([[c, s], [-s, c]]), np.full(len(g), dist)])
    X_cam = X_virtual @ R_ray.T
    expected, _ = cv2.projectPoints(X_cam, np.zeros(3), np.zeros(3), K, None)
    got = cv2.perspectiveTransform(g[None].astype(np.float64), H)[0]
    np.testing.assert_allclose(got, expected[:, 0], atol=1e-6)


def _view(pts, R, t):
    """The (n, n) mask of the target at (R, t) in a silhouette frame around it, and the frame."""
    uv = K @ (t / t[2])
    side = int(2.6 * 3.0 * K[0, 0] / t[2])
    frame = silhouette_frame(K, int(uv[0] - side / 2), int(uv[1] - side / 2), side, 192)
    return splat_mask(pts, R, t, frame)[0], frame


@pytest.mark.parametrize("seed", range(6))
def test_the_search_finds_the_orientation_from_the_outline_alone(bracket, templates, seed):
    pts, centre, _ = bracket
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    z = rng.uniform(12.0, 45.0)
    t = np.array([rng.uniform(-0.15, 0.15) * z, rng.uniform(-0.1, 0.1) * z, z])
    mask, frame = _view(pts, R, t)
    found = search_outline(templates, mask, frame.K, float(np.linalg.norm(t)), candidates=3)
    assert 1 <= len(found) <= 3
    assert [c.score for c in found] == sorted((c.score for c in found), reverse=True)
    for a in range(len(found)):
        for b in range(a):
            assert rotation_angle_deg(found[a].R, found[b].R) >= 30.0
    errors = [float(rotation_angle_deg(R, c.R)) for c in found]
    k = int(np.argmin(errors))
    # the grid's spacing (views ~6.4 deg apart, turns 10 deg), weak perspective and a few pixels of outline
    assert errors[k] < 20.0   # (the refinement's basin is wider: see the rescue test below)
    assert np.linalg.norm(found[k].t - t) < 0.1 * t[2] * 0.15 + 0.3
    for c in found:
        np.testing.assert_allclose(c.R @ c.R.T, np.eye(3), atol=1e-9)


def test_nothing_to_search_gives_nothing(templates):
    empty = np.zeros((64, 64), np.uint8)
    assert search_outline(templates, empty, K, 20.0) == []
    mask = empty.copy()
    mask[20:40, 10:50] = 1
    assert search_outline(templates, mask, K, float("nan")) == []
    assert search_outline(templates, mask, K, 20.0, candidates=0) == []
    with pytest.raises(ValueError):
        search_outline(templates, mask, K, 20.0, angles=0)
    with pytest.raises(ShapeError):
        search_outline(templates, mask[None], K, 20.0)


def test_templates_refuse_nonsense(bracket):
    pts, centre, radius = bracket
    for kwargs in ({"views": 0}, {"grid": 4}):
        with pytest.raises(ValueError):
            OutlineTemplates(pts, centre, radius, **kwargs)
    with pytest.raises(ValueError):
        OutlineTemplates(pts[:50], centre, radius)
    with pytest.raises(ValueError):
        OutlineTemplates(pts, centre, 0.0)


def test_the_search_rescues_a_decision_started_far_from_the_truth(bracket, templates):
    pts, centre, _ = bracket
    R = Rotation.from_euler("xyz", (35, -20, 60), degrees=True).as_matrix()
    t = np.array([0.8, -0.4, 22.0])
    disp = _disparity_of(pts, R, t)
    uv = K @ (t / t[2])
    side = int(2.6 * 3.0 * K[0, 0] / t[2])
    window = (int(uv[0] - side / 2), int(uv[1] - side / 2), side)
    wrong = (Rotation.from_euler("xyz", (0, 80, 0), degrees=True).as_matrix() @ R, t + [0.3, 0.2, 0.5])
    flip = lambda R_, t_: flipped_pose(R_, t_, centre, "z")                           # noqa: E731
    plain = SilhouetteConfig(iterations=10)
    searched = SilhouetteConfig(iterations=10, search_candidates=2)
    lost = decide_outline([wrong], pts, disp, K, 1.0, window, plain, flip=flip)
    assert rotation_angle_deg(lost.best.R, R) > 20.0                   # a local refinement cannot get there
    # the templates are only used when the config asks for candidates
    same = decide_outline([wrong], pts, disp, K, 1.0, window, plain, flip=flip, templates=templates)
    np.testing.assert_array_equal(same.best.R, lost.best.R)
    found = decide_outline([wrong], pts, disp, K, 1.0, window, searched, flip=flip, templates=templates)
    assert rotation_angle_deg(found.best.R, R) < 3.0 and found.best_index in (1, 2)
    assert found.best.chamfer_px < lost.best.chamfer_px


def test_config_refuses_bad_search_settings():
    for bad in ({"search_candidates": -1}, {"search_views": 0}, {"search_angles": 0}, {"search_grid": 4},
                {"search_separation_deg": 200.0}, {"rival_deg": 0.0}, {"rival_deg": 180.0}):
        with pytest.raises(ValueError):
            SilhouetteConfig(**bad)
