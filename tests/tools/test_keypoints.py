"""Tests of spacepose.tools.keypoints (SIFT-FPS)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("trimesh")

from spacepose.errors import DatasetError
from spacepose.tools import keypoints as kp
from spacepose.tools.targets import load_target

def _surface_distance(mesh, points):
    """Exact distance of each point to the closest triangle, (N,)."""
    from trimesh.triangles import closest_point

    tris = np.asarray(mesh.triangles)
    out = []
    for p in points:
        q = closest_point(tris, np.broadcast_to(p, (len(tris), 3)))
        out.append(np.linalg.norm(q - p, axis=1).min())
    return np.array(out)


FAST = kp.KeypointConfig(n_keypoints=8, n_views=8, image_size=192, sift_features=200, seed=0)


def test_fps_picks_extremes_first():
    pts = np.array([[0, 0, 0], [1, 0, 0], [-3, 0, 0], [0, 2, 0], [0.5, 0, 0]], float)
    out = kp.farthest_point_sampling(pts, 3, start=np.zeros(3))
    np.testing.assert_allclose(out, [[-3, 0, 0], [0, 2, 0], [1, 0, 0]])


def test_fps_bad_input():
    with pytest.raises(ValueError, match="shape"):
        kp.farthest_point_sampling(np.zeros((4, 2)), 2, start=np.zeros(3))
    with pytest.raises(ValueError, match="distinct"):
        kp.farthest_point_sampling(np.zeros((5, 3)), 2, start=np.zeros(3))


def test_fibonacci_directions_unit_and_spread():
    d = kp.fibonacci_directions(50)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.abs(d.mean(axis=0)).max() < 0.05


@pytest.mark.parametrize("name", ["tdrs", "mro"])
def test_keypoints_on_surface_spread_and_deterministic(name):
    target = load_target(name)
    a = kp.select_keypoints(target, FAST)
    b = kp.select_keypoints(target, FAST)
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    assert a.keypoints.shape == (8, 3)
    # on the surface: within 2 cm of the mesh
    assert _surface_distance(target.mesh, a.keypoints).max() < 0.02
    # spread: FPS keeps them well apart (target is 5 m long)
    pair = np.linalg.norm(a.keypoints[:, None] - a.keypoints[None], axis=-1)
    assert pair[~np.eye(8, dtype=bool)].min() > 0.3
    np.testing.assert_allclose(a.centre, np.asarray(target.mesh.bounds).mean(axis=0))


def test_save_load_roundtrip_and_no_overwrite(tmp_path):
    target = load_target("tdrs")
    kps = kp.select_keypoints(target, FAST)
    path = tmp_path / "kp.json"
    kp.save_keypoints(kps, path)
    back = kp.load_keypoints(path)
    np.testing.assert_allclose(back.keypoints, kps.keypoints, atol=1e-6)
    assert back.config == FAST
    with pytest.raises(FileExistsError):
        kp.save_keypoints(kps, path)
    path.write_text("{not json")
    with pytest.raises(DatasetError, match="cannot read keypoints"):
        kp.load_keypoints(path)


def test_shipped_keypoints_match_the_command_defaults():
    """The keypoints stored with tdrs are what `spacepose keypoints --target tdrs` selects."""
    target = load_target("tdrs")
    shipped = kp.load_keypoints(target.path.parent / "keypoints.json")
    assert shipped.config == kp.KeypointConfig()
    assert shipped.keypoints.shape == (8, 3)
    assert _surface_distance(target.mesh, shipped.keypoints).max() < 0.02
