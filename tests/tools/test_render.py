"""Renderer: pose distribution, embree, exact ground truth and stereo consistency (small images)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from spacepose.calibration.rig import StereoRig, paper_rig
from spacepose.errors import DatasetError
from spacepose.geometry import disparity_to_depth, project
from spacepose.tools.materials import CLASS_NAMES, MLI, SOLAR, assign_materials
from spacepose.tools.render import (
    REGIMES,
    PoseSampler,
    StereoCamera,
    embree_scene,
    quaternion_to_rotation,
    render_stereo,
    rotation_to_quaternion,
    sample_scene,
)
from spacepose.tools.targets import load_target

SIZE = (320, 240)


@pytest.fixture(scope="module")
def camera():
    return StereoCamera.from_rig(paper_rig(*SIZE))


def _frames(name, camera, n=4, seed=11):
    target = load_target(name)
    sampler = PoseSampler(camera, target.bounding_radius)
    out = []
    for i in range(n):
        scene = sample_scene(target, camera, np.random.default_rng([seed, i]), REGIMES[i % 4], sampler)
        out.append((scene, render_stereo(target, camera, scene)))
    return target, out


@pytest.fixture(scope="module", params=["tdrs", "mro"])
def rendered(request, camera):
    return _frames(request.param, camera)


def _brute_force_depth(tris: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Nearest hit parameter of rays from the origin along dirs (z = 1) over all triangles (Moller-Trumbore)."""
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    out = np.full(len(dirs), np.inf)
    for i, d in enumerate(dirs):
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = -v0
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if np.any(hit):
            out[i] = t[hit].min()
    return out


class TestStereoCamera:
    def test_paper_rig(self, camera):
        assert camera.size == SIZE
        assert camera.fx == pytest.approx(400.0)
        assert camera.baseline_m == pytest.approx(1.0)

    def test_rejects_non_ideal_rig(self):
        rig = paper_rig(*SIZE)
        bent = StereoRig(rig.M1, rig.D1, rig.M2, np.array([0.1, 0, 0, 0, 0.0]), rig.R, rig.T, rig.image_size)
        with pytest.raises(DatasetError, match="ideal parallel rig"):
            StereoCamera.from_rig(bent)


class TestPoseSampler:
    def test_sphere_inside_both_views(self, camera):
        target = load_target("tdrs")
        sampler = PoseSampler(camera, target.bounding_radius)
        rng = np.random.default_rng(0)
        r = target.bounding_radius
        w, h = SIZE
        zs = []
        for _ in range(300):
            R, t = sampler.sample(rng)
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(R) == pytest.approx(1.0)
            zs.append(t[2])
            for cx in (0.0, camera.baseline_m):  # sphere silhouette inside each image
                c = t - np.array([cx, 0, 0])
                u, v = project(c[None], camera.K)[0]
                ang = math.asin(r / np.linalg.norm(c))
                half = camera.fx * math.tan(ang) * 0.9  # the silhouette's half size, conservatively
                assert -0.5 + half <= u <= w - 0.5 - half and -0.5 + half <= v <= h - 0.5 - half
        assert 10.0 <= min(zs) and max(zs) <= 50.0
        assert np.mean(zs) == pytest.approx(30.0, abs=2.5)

    def test_depth_range_that_cannot_fit(self, camera):
        with pytest.raises(DatasetError, match="cannot fit the target"):
            PoseSampler(camera, load_target("tdrs").bounding_radius, (2.0, 5.0))

    @pytest.mark.parametrize("bad", [(0.0, 10.0), (20.0, 10.0), (float("nan"), 10.0)])
    def test_bad_depth_range(self, camera, bad):
        with pytest.raises(DatasetError):
            PoseSampler(camera, 2.5, bad)

    def test_quaternion_roundtrip(self):
        rng = np.random.default_rng(3)
        for _ in range(50):
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            q = q if q[0] >= 0 else -q
            np.testing.assert_allclose(rotation_to_quaternion(quaternion_to_rotation(q)), q, atol=1e-12)


class TestMaterials:
    @pytest.mark.parametrize("name", ["tdrs", "mro"])
    def test_rule_finds_bus_panels_and_dishes(self, name):
        pmap = assign_materials(load_target(name))
        present = {CLASS_NAMES[c] for c in np.unique(pmap.part_class)}
        assert {"mli", "solar", "dish", "structure"} <= present
        assert np.sum(pmap.part_class == SOLAR) >= 4 and np.sum(pmap.part_class == MLI) >= 1


class TestRender:
    def test_uses_embree(self):
        from embreex.rtcore_scene import EmbreeScene

        assert isinstance(embree_scene(load_target("tdrs")), EmbreeScene)

    def test_outputs(self, rendered, camera):
        _, frames = rendered
        w, h = SIZE
        for _, r in frames:
            for img in (r.left, r.right):
                assert img.shape == (h, w, 3) and img.dtype == np.float32
                assert 0.0 <= img.min() and img.max() <= 1.0
            assert r.disparity.dtype == np.float32 and r.depth.dtype == np.float32
            assert r.mask.sum() > 50 and r.mask_right.sum() > 50
            np.testing.assert_array_equal(r.disparity > 0, r.mask)
            assert np.all(r.disparity[~r.mask] == 0) and np.all(r.depth[~r.mask] == 0)

    def test_projected_vertices_fall_on_the_mask(self, rendered, camera):
        target, frames = rendered
        for scene, r in frames:
            pts = target.mesh.vertices @ scene.R.T + scene.t
            uv = np.rint(project(pts, camera.K)).astype(int)
            grown = cv2.dilate(r.mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0  # thin struts fall between pixel centres
            assert grown[uv[:, 1], uv[:, 0]].mean() > 0.98

    def test_depth_from_disparity_is_raycast_depth(self, rendered, camera):
        target, frames = rendered
        tris = target.mesh.triangles
        for scene, r in frames:
            depth = disparity_to_depth(r.disparity, camera.fx, camera.baseline_m)
            np.testing.assert_allclose(depth[r.mask], r.depth[r.mask], rtol=1e-5)
            assert np.all(r.depth[r.mask] > 10.0 - target.bounding_radius)
            ys, xs = np.nonzero(r.mask)
            pick = np.random.default_rng(0).choice(len(xs), size=min(30, len(xs)), replace=False)
            dirs = np.stack([(xs[pick] - camera.K[0, 2]) / camera.fx, (ys[pick] - camera.K[1, 2]) / camera.fx, np.ones(len(pick))], 1)
            z = _brute_force_depth(tris @ scene.R.T + scene.t, dirs)  # independent of embree
            np.testing.assert_allclose(r.depth[ys[pick], xs[pick]], z, rtol=1e-4, atol=1e-3)

    def test_right_image_at_x_minus_d_reproduces_left(self, rendered):
        _, frames = rendered
        medians, close = [], []
        for _, r in frames:
            ys, xs = np.nonzero(r.mask)
            xr = xs - r.disparity[ys, xs]
            x0 = np.floor(xr).astype(int)
            ok = (x0 >= 0) & (x0 + 1 < r.mask.shape[1])
            ys, xs, xr, x0 = ys[ok], xs[ok], xr[ok], x0[ok]
            zl = r.depth[ys, xs]
            same = (np.abs(r.depth_right[ys, x0] - zl) < 0.01 * zl) & (np.abs(r.depth_right[ys, x0 + 1] - zl) < 0.01 * zl)
            a = (xr - x0)[same, None]
            sampled = r.right[ys[same], x0[same]] * (1 - a) + r.right[ys[same], x0[same] + 1] * a
            diff = np.abs(sampled - r.left[ys[same], xs[same]]).max(axis=1)
            assert same.mean() > 0.3
            medians.append(np.median(diff))
            close.append(diff < 0.15)
            assert np.mean(diff < 0.15) > 0.6  # view-dependent specular highlights differ, the rest matches
        assert np.median(medians) < 0.03
        assert np.mean(np.concatenate(close)) > 0.8

    def test_background_identical_in_both_views(self, rendered):
        _, frames = rendered
        for _, r in frames:
            both = ~r.mask & ~r.mask_right
            np.testing.assert_array_equal(r.left[both], r.right[both])

    def test_not_a_grey_blob(self, rendered):
        _, frames = rendered
        for scene, r in frames:
            vals = r.left[r.mask].mean(axis=1)
            if scene.regime in ("sun", "mixed"):
                assert vals.max() > 0.6 and np.percentile(vals, 5) < 0.3
            assert vals.std() > 0.03

    def test_deterministic(self, camera):
        _, a = _frames("tdrs", camera, n=2, seed=5)
        _, b = _frames("tdrs", camera, n=2, seed=5)
        for (_, ra), (_, rb) in zip(a, b):
            np.testing.assert_array_equal(ra.left, rb.left)
            np.testing.assert_array_equal(ra.disparity, rb.disparity)
