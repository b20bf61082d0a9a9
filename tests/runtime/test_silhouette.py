"""Tests of spacepose.silhouette: the frame, the splat, the observed mask, outline refinement, the decision."""

import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _bundle_fixtures import make_bundle, manifest  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.errors import BundleError, ShapeError  # noqa: E402
from spacepose.flip import flipped_pose  # noqa: E402
from spacepose.registration import SurfaceModel, rotation_angle_deg  # noqa: E402
from spacepose.silhouette import (OutlineDecision, SilhouetteConfig, align_centroid, chamfer_px,  # noqa: E402
                                  contour, decide_outline, observed_edges, observed_mask, polish_pose, refine_outline,
                                  silhouette_frame, splat_mask)

K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])
CENTRE = np.zeros(3)


def _slab(lo, hi, n_per_m2, rng):
    """Area-uniform samples and outward normals of the faces of the box ``lo``..``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pts, nrm = [], []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        m = max(16, int((hi[a] - lo[a]) * (hi[b] - lo[b]) * n_per_m2))
        for side, value in ((-1.0, lo[axis]), (1.0, hi[axis])):
            p = np.empty((m, 3))
            p[:, a] = rng.uniform(lo[a], hi[a], m)
            p[:, b] = rng.uniform(lo[b], hi[b], m)
            p[:, axis] = value
            n = np.zeros((m, 3))
            n[:, axis] = side
            pts.append(p)
            nrm.append(n)
    return np.vstack(pts), np.vstack(nrm)


@pytest.fixture(scope="module")
def plate():
    """A 4 x 2 x 0.4 m plate with a 1 x 0.8 m tab on one short side, off centre: its half turn about
    z moves the tab to the other side (the outline tells the two apart, a depth map barely)."""
    rng = np.random.default_rng(0)
    p1, n1 = _slab((-2, -1, -0.2), (2, 1, 0.2), 3000, rng)
    p2, n2 = _slab((2, 0.1, -0.2), (3, 0.9, 0.2), 3000, rng)
    return np.vstack([p1, p2]), np.vstack([n1, n2])


def _pose(deg=(20, -15, 30), t=(0.3, -0.2, 20.0)):
    return Rotation.from_euler("xyz", deg, degrees=True).as_matrix(), np.asarray(t, float)


def _disparity_of(points, R, t, shape=(480, 640), baseline=1.0):
    """A full-frame disparity map holding the target's splat at its disparity (0 elsewhere)."""
    frame = silhouette_frame(K, 0, 0, max(shape), 4096)
    mask, _, _ = splat_mask(points, R, t, frame)
    disp = np.zeros(shape, np.float32)
    disp[mask[: shape[0], : shape[1]] > 0] = K[0, 0] * baseline / float(t[2])
    return disp


def test_frame_intrinsics_follow_the_crop_and_scale():
    frame = silhouette_frame(K, 100, 60, 400, 160)
    assert frame.size == 160 and frame.scale == pytest.approx(0.4)
    X = np.array([[0.5, -0.3, 12.0], [-1.0, 0.7, 30.0]])
    u_full = X[:, :2] / X[:, 2:] * K[0, 0] + K[:2, 2]
    u_frame = X[:, :2] / X[:, 2:] * frame.K[0, 0] + frame.K[:2, 2]
    np.testing.assert_allclose(u_frame, (u_full - [100, 60] + 0.5) * 0.4 - 0.5, atol=1e-9)
    assert silhouette_frame(K, 0, 0, 100, 160).scale == 1.0   # never upscaled


def test_splat_and_contour_of_a_disc():
    rng = np.random.default_rng(1)
    r = np.sqrt(rng.uniform(0, 1, 40000)) * 1.0
    a = rng.uniform(0, 2 * np.pi, 40000)
    disc = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(r)], axis=1)
    frame = silhouette_frame(K, 220, 140, 200, 200)
    mask, ij, inside = splat_mask(disc, np.eye(3), np.array([0, 0, 20.0]), frame)
    assert inside.all()
    radius_px = 800 / 20.0
    assert mask.sum() == pytest.approx(np.pi * radius_px ** 2, rel=0.05)
    edge = contour(mask)
    ys, xs = np.nonzero(edge)
    centre = frame.K[:2, 2]
    np.testing.assert_allclose(np.hypot(xs - centre[0], ys - centre[1]), radius_px, atol=1.5)


def test_splat_matches_opencv_projection():
    rng = np.random.default_rng(5)
    pts = rng.uniform(-2.0, 2.0, (5000, 3))
    R, t = _pose((20, -35, 50), (0.6, -0.4, 18.0))
    frame = silhouette_frame(K, 180, 100, 300, 150)
    mask, ij, inside = splat_mask(pts, R, t, frame)
    uv, _ = cv2.projectPoints(pts, cv2.Rodrigues(R)[0], t, frame.K, None)
    ref = np.rint(uv[:, 0]).astype(int)
    ref_inside = np.all((ref >= 0) & (ref < frame.size), axis=1)
    np.testing.assert_array_equal(inside, ref_inside)
    np.testing.assert_array_equal(ij[inside], ref[inside])
    raw = np.zeros((frame.size, frame.size), np.uint8)
    raw[ref[ref_inside, 1], ref[ref_inside, 0]] = 1
    np.testing.assert_array_equal(mask, cv2.morphologyEx(raw, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)))


def _splat_per_point(points, R, t, frame):
    """The splat as it was until session 39: (S, 3) points projected row by row (the reference the
    row-wise, in-place splat must equal bit for bit)."""
    n = frame.size
    X = points @ np.asarray(R, dtype=points.dtype).T + np.asarray(t, dtype=points.dtype)
    K32 = frame.K.astype(points.dtype)
    z = np.maximum(X[:, 2], 1e-6)
    uv = np.empty((len(X), 2), dtype=np.result_type(X, K32))
    np.add(K32[0, 0] * X[:, 0] / z, K32[0, 2], out=uv[:, 0])
    np.add(K32[1, 1] * X[:, 1] / z, K32[1, 2], out=uv[:, 1])
    if not np.isfinite(uv).all():
        uv = np.nan_to_num(uv, nan=-1.0)
    np.clip(uv, -1.0, float(n), out=uv)
    ij = np.rint(uv, out=uv).astype(np.int32)
    u = ij.view(np.uint32)
    inside = (u[:, 0] < n) & (u[:, 1] < n) & (X[:, 2] > 1e-3)
    mask = np.zeros((n, n), np.uint8)
    mask.reshape(-1)[(ij[:, 1].astype(np.int64) * n + ij[:, 0])[inside]] = 1
    return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)), ij, inside


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_splat_equals_the_per_point_projection_bit_for_bit(dtype):
    """Random poses, points behind the camera and off the frame, and a NaN pose."""
    rng = np.random.default_rng(39)
    pts = rng.uniform(-3.0, 3.0, (6000, 3)).astype(dtype)
    frame = silhouette_frame(K, 150, 90, 320, 192)
    poses = [_pose(rng.uniform(-180, 180, 3), (rng.uniform(-2, 2), rng.uniform(-2, 2), z))
             for z in (0.5, 2.0, 15.0, 25.0, 60.0)]
    poses.append((np.full((3, 3), np.nan), np.zeros(3)))
    for R, t in poses:
        got, want = splat_mask(pts, R, t, frame), _splat_per_point(pts, R, t, frame)
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)


def test_contour_is_the_mask_pixels_with_a_background_neighbour():
    mask = (np.random.default_rng(6).uniform(size=(40, 50)) < 0.7).astype(np.uint8)
    padded = np.pad(mask, 1)
    shifted = [padded[1 + dy:41 + dy, 1 + dx:51 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    ref = (mask > 0) & np.any([s == 0 for s in shifted], axis=0)
    np.testing.assert_array_equal(contour(mask), ref)


def test_observed_mask_crops_thresholds_and_pads():
    disp = np.zeros((480, 640), np.float32)
    disp[200:260, 300:380] = 20.0
    disp[0:10, 0:10] = 2.0                                  # far: below the threshold
    frame = silhouette_frame(K, -40, -40, 480, 480)         # reaches beyond the image's corner
    obs = observed_mask(disp, frame, 5.0)
    assert obs.shape == (480, 480) and obs.sum() == 60 * 80
    assert obs[240:300, 340:420].all()
    small = observed_mask(disp, silhouette_frame(K, -40, -40, 480, 120), 5.0)
    assert small.shape == (120, 120) and small.sum() == pytest.approx(60 * 80 / 16, rel=0.1)
    with pytest.raises(ShapeError):
        observed_mask(np.zeros((4, 4, 3), np.float32), frame, 1.0)


def test_chamfer_is_zero_for_the_same_mask_and_grows_with_a_shift():
    m = np.zeros((100, 100), np.uint8)
    cv2.rectangle(m, (30, 30), (70, 60), 1, -1)
    assert chamfer_px(m, m, 8.0) == 0.0
    shifted = np.roll(m, 3, axis=1)
    assert 1.0 < chamfer_px(shifted, m, 8.0) <= 3.0
    assert chamfer_px(shifted, m, 8.0, scale=0.5) == pytest.approx(2 * chamfer_px(shifted, m, 8.0))
    assert chamfer_px(np.zeros_like(m), m, 8.0, scale=0.5) == 16.0   # nothing to compare: the cap


def test_align_centroid_moves_the_pose_onto_the_observed_outline(plate):
    """A pose a few degrees and 0.3 m off sideways: the shift puts the centre back within a few cm in the image
    plane and keeps the range; a cut or empty outline gives no shift."""
    pts, _ = plate
    R, t = _pose()
    frame = silhouette_frame(K, 160, 80, 320, 192)
    obs = observed_mask(_disparity_of(pts, R, t), frame, 10.0)
    dR = Rotation.from_rotvec(np.radians(4) * np.array([0.6, -0.5, 0.62])).as_matrix()
    t0 = t + np.array([0.25, -0.15, 0.4])
    aligned = align_centroid(dR @ R, t0, pts, obs, frame)
    assert aligned[2] == t0[2]
    before, after = (np.linalg.norm((dR @ R @ CENTRE + v - (R @ CENTRE + t))[:2]) for v in (t0, aligned))
    assert after < 0.05 < 0.25 < before
    # exactly the pose: no shift beyond the splat's rounding
    assert np.linalg.norm(align_centroid(R, t, pts, obs, frame) - t) < 0.01
    # the same at a quarter of the resolution (the frame's own pixels)
    small = silhouette_frame(K, 160, 80, 320, 80)
    obs_small = observed_mask(_disparity_of(pts, R, t), small, 10.0)
    assert np.linalg.norm((align_centroid(dR @ R, t0, pts, obs_small, small) - t)[:2]) < 0.08
    # a window that cuts the target, or an empty outline: no shift
    cut = silhouette_frame(K, 300, 80, 120, 192)
    assert align_centroid(R, t, pts, observed_mask(_disparity_of(pts, R, t), cut, 10.0), cut) is None
    assert align_centroid(R, t, pts, np.zeros_like(obs), frame) is None
    with pytest.raises(ShapeError):
        align_centroid(R, t, pts, obs[:-1], frame)


def test_refinement_recovers_a_perturbed_pose(plate):
    pts, nrm = plate
    R, t = _pose()
    disp = _disparity_of(pts, R, t)
    frame = silhouette_frame(K, 160, 80, 320, 192)
    obs = observed_mask(disp, frame, 10.0)
    dR = Rotation.from_rotvec(np.radians(6) * np.array([0.6, -0.5, 0.62])).as_matrix()
    R0, t0 = dR @ R, t + np.array([0.15, -0.1, 0.3])
    cam = pts @ R.T + t
    stereo = cam[np.einsum("ij,ij->i", nrm @ R.T, cam) < 0][::10]
    fit = refine_outline(R0, t0, pts, obs, frame, SilhouetteConfig(iterations=15), stereo_points=stereo,
                         surface=SurfaceModel(pts, nrm), tau_m=0.2)
    start = refine_outline(R0, t0, pts, obs, frame, SilhouetteConfig(iterations=0))
    assert rotation_angle_deg(fit.R, R) < 1.5 < rotation_angle_deg(R0, R)
    assert np.linalg.norm(fit.t - t) < 0.1
    assert fit.chamfer_px < 0.6 < start.chamfer_px


def test_refinement_with_the_outline_edges_made_once_is_the_same(plate):
    """decide_outline makes the observed outline's edges once for all its candidates: a refinement given them
    returns what it returns when it makes them itself, bit for bit; edges of another outline are refused."""
    pts, nrm = plate
    R, t = _pose()
    frame = silhouette_frame(K, 160, 80, 320, 192)
    obs = observed_mask(_disparity_of(pts, R, t), frame, 10.0)
    edges = observed_edges(obs)
    assert np.array_equal(np.stack([edges.ey, edges.ex], axis=1), np.argwhere(contour(obs)))
    assert np.all(edges.label[edges.flat] == np.arange(1, len(edges.flat) + 1)) and np.all(edges.dist[edges.flat] == 0)
    cam = pts @ R.T + t
    stereo = cam[np.einsum("ij,ij->i", nrm @ R.T, cam) < 0][::10]
    surface = SurfaceModel(pts, nrm)
    for deg in (4.0, 9.0):
        dR = Rotation.from_rotvec(np.radians(deg) * np.array([0.6, -0.5, 0.62])).as_matrix()
        R0, t0 = dR @ R, t + np.array([0.15, -0.1, 0.3])
        own = refine_outline(R0, t0, pts, obs, frame, stereo_points=stereo, surface=surface, tau_m=0.2)
        given = refine_outline(R0, t0, pts, obs, frame, stereo_points=stereo, surface=surface, tau_m=0.2, edges=edges)
        assert np.array_equal(own.R, given.R) and np.array_equal(own.t, given.t)
        assert own.chamfer_px == given.chamfer_px and own.points_res == given.points_res
    other = observed_edges(observed_mask(_disparity_of(pts, R, t), silhouette_frame(K, 160, 80, 320, 96), 10.0))
    with pytest.raises(ShapeError, match="edges"):
        refine_outline(R, t, pts, obs, frame, edges=other)


def test_range_weight_keeps_a_fattened_outline_from_pulling_the_pose_near(plate):
    """A stereo outline a little too large (disparity carried into the sky) makes the outline prefer a
    nearer pose; with range_weight 0 the range is the stereo points' and stays at the truth."""
    pts, nrm = plate
    R, t = _pose()
    disp = _disparity_of(pts, R, t)
    fat = cv2.dilate((disp > 0).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=1) > 0
    disp = np.where(fat, disp.max(), 0.0).astype(np.float32)
    frame = silhouette_frame(K, 160, 80, 320, 320)
    obs = observed_mask(disp, frame, 10.0)
    cam = pts @ R.T + t
    stereo = cam[np.einsum("ij,ij->i", nrm @ R.T, cam) < 0][::10]
    kwargs = dict(stereo_points=stereo, surface=SurfaceModel(pts, nrm), tau_m=0.2)
    plain = refine_outline(R, t, pts, obs, frame, SilhouetteConfig(), **kwargs)
    ranged = refine_outline(R, t, pts, obs, frame, SilhouetteConfig(range_weight=0.0), **kwargs)
    assert t[2] - plain.t[2] > 0.2                              # pulled near by the fat outline
    assert abs(ranged.t[2] - t[2]) < 0.05
    with pytest.raises(ValueError):
        SilhouetteConfig(range_weight=1.5)


def test_the_polish_refines_the_decided_pose_with_its_own_range_weight(plate):
    """An outline a little large pulls the range near. The decision (range_weight 0) keeps the stereo
    points' range; the polish is one more refinement against the same outline with
    ``polish_range_weight``, and a polish that would move the pose too far is not used."""
    pts, nrm = plate
    R, t = _pose()
    disp = _disparity_of(pts, R, t)
    fat = cv2.dilate((disp > 0).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=1) > 0
    disp = np.where(fat, disp.max(), 0.0).astype(np.float32)
    cam = pts @ R.T + t
    stereo = cam[np.einsum("ij,ij->i", nrm @ R.T, cam) < 0][::10]
    kwargs = dict(stereo_points=stereo, surface=SurfaceModel(pts, nrm), tau_m=0.2)
    config = SilhouetteConfig(max_side_px=320, range_weight=0.0, polish=1)
    dec = decide_outline([(R, t)], pts, disp, K, 1.0, (160, 80, 320), config,
                         flip=lambda R_, t_: flipped_pose(R_, t_, CENTRE, "z"), **kwargs)
    assert abs(dec.best.t[2] - t[2]) < 0.05                            # the stereo points' range
    assert dec.frame is not None and dec.observed.shape == (dec.frame.size, dec.frame.size)
    polished = {w: polish_pose(dec, dec.best.R, dec.best.t, pts, dataclasses.replace(config, polish_range_weight=w),
                               **kwargs) for w in (0.0, 1.0)}
    assert polished[1.0].t[2] < t[2] - 0.3 < polished[0.0].t[2]       # the fat outline's pull, at full weight only
    same = refine_outline(dec.best.R, dec.best.t, pts, dec.observed, dec.frame,
                          dataclasses.replace(config, range_weight=1.0), **kwargs)
    np.testing.assert_array_equal(polished[1.0].t, same.t)
    assert rotation_angle_deg(polished[1.0].R, R) < 5.0
    assert polish_pose(dec, dec.best.R, dec.best.t, pts, dataclasses.replace(config, polish_max_m=1e-3),
                       **kwargs) is None                                # moved too far: not used
    bare = OutlineDecision(best=dec.best, other=dec.other, best_index=0, margin_px=0.0, turned_deg=float("nan"))
    assert polish_pose(bare, dec.best.R, dec.best.t, pts, config, **kwargs) is None


def test_the_outline_tells_the_pose_from_its_flip(plate):
    pts, nrm = plate
    R, t = _pose()
    disp = _disparity_of(pts, R, t)
    dR = Rotation.from_rotvec(np.radians(4) * np.array([0.0, 0.6, 0.8])).as_matrix()
    near = (dR @ R, t + np.array([0.1, 0.05, 0.0]))
    flip = flipped_pose(*near, CENTRE, "z")
    config = SilhouetteConfig(iterations=12)
    for order in ([near, flip], [flip, near]):
        dec = decide_outline(order, pts, disp, K, 1.0, (160, 80, 320), config,
                             flip=lambda R_, t_: flipped_pose(R_, t_, CENTRE, "z"))
        assert rotation_angle_deg(dec.best.R, R) < 2.0
        assert dec.turned_deg > 150.0
        assert dec.margin_px > 1.0 and dec.decided(config)


def test_the_flip_of_the_best_fit_rescues_a_candidate_too_far_to_converge(plate):
    pts, _ = plate
    R, t = _pose()
    disp = _disparity_of(pts, R, t)
    config = SilhouetteConfig(iterations=12)
    # only the flipped pose is offered: the refined flip of the refined flip is the answer
    only_flip = [flipped_pose(R, t, CENTRE, "z")]
    dec = decide_outline(only_flip, pts, disp, K, 1.0, (160, 80, 320), config,
                         flip=lambda R_, t_: flipped_pose(R_, t_, CENTRE, "z"))
    # (the outline alone fixes the tilt of a plate seen face-on only loosely: a few degrees)
    assert dec.best_index == 1 and rotation_angle_deg(dec.best.R, R) < 5.0 and dec.best.chamfer_px < 0.8
    # without the flip there is no rival: the margin is the cap, and the (wrong) pose is what it is
    alone = decide_outline(only_flip, pts, disp, K, 1.0, (160, 80, 320), config)
    assert alone.best_index == 0 and np.isnan(alone.turned_deg) and np.isnan(alone.other.R).all()
    with pytest.raises(ValueError):
        decide_outline([], pts, disp, K, 1.0, (160, 80, 320), config)


def test_the_points_weight_decides_where_two_outlines_fit_alike():
    """A plate with a block on its front face, seen face-on: turned over about x, its outline is the
    same rectangle, and the chamfer cannot choose; the stereo points (the block comes towards the
    camera) can, with ``points_weight``."""
    rng = np.random.default_rng(5)
    plate_p, plate_n = _slab((-2, -1, -0.1), (2, 1, 0.1), 2000, rng)
    block_p, block_n = _slab((-0.5, -0.5, -1.1), (0.5, 0.5, -0.1), 2000, rng)
    pts, nrm = np.vstack([plate_p, block_p]), np.vstack([plate_n, block_n])
    R, t = np.eye(3), np.array([0.2, -0.1, 20.0])                    # face-on, the block (-z) towards the camera
    over = Rotation.from_euler("x", 180, degrees=True).as_matrix()
    turned = (R @ over, t)                                             # the block behind, the same outline
    disp = _disparity_of(pts, R, t)
    cam = pts @ R.T + t
    visible = np.einsum("ij,ij->i", nrm @ R.T, cam) < 0
    stereo = cam[visible & ((np.abs(pts[:, 0]) > 0.55) | (np.abs(pts[:, 1]) > 0.55) | (pts[:, 2] < -1.0))][::4]
    kwargs = dict(stereo_points=stereo, surface=SurfaceModel(pts, nrm), tau_m=0.2)
    window = (160, 80, 320)
    config = SilhouetteConfig(iterations=4, points_weight=2.0)
    fits = {name: refine_outline(*pose, pts, observed_mask(disp, silhouette_frame(K, *window, 192), 10.0),
                                 silhouette_frame(K, *window, 192), config, **kwargs)
            for name, pose in (("true", (R, t)), ("turned", turned))}
    assert abs(fits["true"].chamfer_px - fits["turned"].chamfer_px) < 0.3          # the outline cannot tell
    assert 0.0 <= fits["true"].points_res < 0.15 < 0.3 < fits["turned"].points_res <= 3.0   # the block: 1/8 of the face
    assert fits["turned"].score(config) == pytest.approx(fits["turned"].chamfer_px + 2.0 * fits["turned"].points_res)
    for order in ([(R, t), turned], [turned, (R, t)]):
        dec = decide_outline(order, pts, disp, K, 1.0, window, config, **kwargs)
        assert rotation_angle_deg(dec.best.R, R) < 3.0 and dec.margin_px > 0.5
    # unweighted, the points are not measured and the margin is the chamfer's alone
    plain = decide_outline([(R, t), turned], pts, disp, K, 1.0, window, SilhouetteConfig(iterations=4), **kwargs)
    assert plain.best.points_res == 0.0 and plain.margin_px < 0.3
    with pytest.raises(ValueError):
        SilhouetteConfig(points_weight=-1.0)


def test_an_empty_outline_decides_nothing(plate):
    pts, _ = plate
    R, t = _pose()
    disp = np.zeros((480, 640), np.float32)                  # the stereo graph saw nothing
    config = SilhouetteConfig()
    dec = decide_outline([(R, t), flipped_pose(R, t, CENTRE, "z")], pts, disp, K, 1.0, (160, 80, 320), config)
    assert not dec.decided(config)
    np.testing.assert_allclose(dec.best.R, R, atol=1e-12)      # no step was taken


def test_config_refuses_nonsense():
    for bad in ({"max_side_px": 4}, {"trunc_px": 0.0}, {"contour_points": 3}, {"iterations": -1},
                {"sigma_px": -1.0}, {"polish": 2}, {"polish_range_weight": 1.5}, {"polish_max_deg": 0.0},
                {"polish_max_m": -1.0}):
        with pytest.raises(ValueError):
            SilhouetteConfig(**bad)


def _outline_manifest(**section):
    data = manifest()
    rng = np.random.default_rng(0)
    data["target"]["surface_points"] = rng.normal(size=(50, 3)).tolist()
    data["target"]["silhouette_points"] = rng.normal(size=(200, 3)).tolist()
    data["registration"] = {}
    data["silhouette"] = section
    return data


def test_bundle_silhouette_section(tmp_path):
    bundle = load_bundle(make_bundle(tmp_path / "b", _outline_manifest(max_chamfer_px=1.5, min_margin_px=0.3)))
    assert bundle.silhouette == SilhouetteConfig(max_chamfer_px=1.5, min_margin_px=0.3)
    assert bundle.silhouette_points.shape == (200, 3)
    voting = load_bundle(make_bundle(tmp_path / "v", _outline_manifest(image_vote=1, range_weight=0, image_veto_score=0,
                                                                     image_min_pixels=16)))
    assert voting.silhouette == SilhouetteConfig(image_vote=1, range_weight=0.0, image_veto_score=0.0, image_min_pixels=16)
    polished = load_bundle(make_bundle(tmp_path / "pp", _outline_manifest(polish=1, polish_range_weight=0)))
    assert polished.silhouette == SilhouetteConfig(polish=1, polish_range_weight=0.0)
    off = load_bundle(make_bundle(tmp_path / "po", _outline_manifest(polish=0)))
    assert off.silhouette.polish == 0
    searched = load_bundle(make_bundle(tmp_path / "se", _outline_manifest(search_candidates=3, points_weight=4,
                                                                        search_separation_deg=0, rival_deg=30)))
    assert searched.silhouette == SilhouetteConfig(search_candidates=3, points_weight=4.0, search_separation_deg=0.0,
                                                   rival_deg=30.0)
    plain = load_bundle(make_bundle(tmp_path / "plain"))
    assert plain.silhouette is None and plain.silhouette_points.shape == (0, 3)


@pytest.mark.parametrize("edit, match", [
    (lambda d: d["silhouette"].update(bogus=1), "unknown keys"),
    (lambda d: d["silhouette"].update(max_chamfer_px=-1), "max_chamfer_px"),
    (lambda d: d["silhouette"].update(iterations=1.5), "iterations"),
    (lambda d: d["silhouette"].update(image_veto_score=0.5), "image_veto_score"),
    (lambda d: d["silhouette"].update(range_weight=2), "invalid silhouette config"),
    (lambda d: d["silhouette"].update(polish=2), "invalid silhouette config"),
    (lambda d: d["silhouette"].update(polish_max_deg=0), "polish_max_deg"),
    (lambda d: d["silhouette"].update(points_weight=-1), "points_weight"),
    (lambda d: d["silhouette"].update(search_candidates=-1), "search_candidates"),
    (lambda d: d["silhouette"].update(search_grid=4), "invalid silhouette config"),
    (lambda d: d["target"].update(silhouette_points=[[0, 0, 0]] * 10), "at least 100"),
    (lambda d: d.pop("registration"), "registration"),
    (lambda d: d.update(silhouette=[1, 2]), "must be an object"),
    (lambda d: d["target"].update(silhouette_points=[[0, 0]] * 200), "silhouette_points"),
])
def test_bundle_refuses_bad_silhouette_sections(tmp_path, edit, match):
    data = _outline_manifest()
    edit(data)
    with pytest.raises(BundleError, match=match):
        load_bundle(make_bundle(tmp_path / "b", data))


def test_outline_pixels_do_not_depend_on_the_image_resolution(plate):
    """The same view at 640x480 and 1280x960 (window twice as large): the same chamfer and margin
    in outline pixels, so one gate serves both rigs."""
    pts, _ = plate
    R, t = _pose()
    start = (Rotation.from_rotvec(np.radians(3) * np.array([0.0, 0.6, 0.8])).as_matrix() @ R, t + [0.05, 0.0, 0.0])
    K2 = K.copy()
    K2[:2] *= 2.0
    K2[:2, 2] += 0.5                         # pixel centres at integers: cx' = (cx + 0.5) * 2 - 0.5
    frame2 = silhouette_frame(K2, 0, 0, 1280, 4096)
    mask2, _, _ = splat_mask(pts, R, t, frame2)
    disp2 = np.zeros((960, 1280), np.float32)
    disp2[mask2[:960] > 0] = K2[0, 0] / t[2]
    config = SilhouetteConfig(iterations=0)   # the same pose compared at both resolutions
    lo = decide_outline([start], pts, _disparity_of(pts, R, t), K, 1.0, (160, 80, 320), config,
                        flip=lambda R_, t_: flipped_pose(R_, t_, CENTRE, "z"))
    hi = decide_outline([start], pts, disp2, K2, 1.0, (320, 160, 640), config,
                        flip=lambda R_, t_: flipped_pose(R_, t_, CENTRE, "z"))
    assert hi.best.chamfer_px == pytest.approx(lo.best.chamfer_px, rel=0.25, abs=0.1)
    assert hi.margin_px == pytest.approx(lo.margin_px, rel=0.25)
    # a far target (window smaller than the frame) is measured on the same scale: stricter in image px
    far = silhouette_frame(K, 0, 0, 96, 192)
    assert far.size == 96 and far.scale == 1.0


# ------------------------------------------------------------------ in the estimator
def _estimator(tmp_path, registration, silhouette):
    """The tiny bundle with the synthetic pair's target for registration and outline: its 120 x 80 px
    rectangle at the tiny stereo graph's disparity (88.8 px, 9.0 m) is a 1.35 x 0.9 m plate."""
    from _bundle_fixtures import synthetic_pair  # noqa: F401  (the pair these bundles are for)

    from spacepose.calibration.rig import paper_rig
    from spacepose.estimator import PoseEstimator

    g = np.stack(np.meshgrid(np.linspace(-0.675, 0.675, 28), np.linspace(-0.45, 0.45, 19), indexing="ij"), -1)
    surface = np.hstack([g.reshape(-1, 2), np.zeros((g.shape[0] * g.shape[1], 1))])
    rng = np.random.default_rng(0)
    dense = np.stack([rng.uniform(-0.675, 0.675, 6000), rng.uniform(-0.45, 0.45, 6000), np.zeros(6000)], axis=1)
    target = dict(manifest()["target"], surface_points=surface.tolist(),
                  surface_normals=np.tile([0.0, 0.0, 1.0], (len(surface), 1)).tolist(),
                  silhouette_points=dense.tolist())
    folder = make_bundle(tmp_path / "b", manifest_overrides={
        "target": target, "voting": {"min_points": 32, "flip_axis": "z"}, "registration": registration,
        "silhouette": silhouette})
    return PoseEstimator(paper_rig(640, 480), bundle=load_bundle(folder), threads=1)


def test_the_estimator_decides_by_the_outline(tmp_path):
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()
    # the registration never decides (min_margin 0.99): what is valid, the outline decided
    est = _estimator(tmp_path, {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0})
    res = est.estimate(left, right)
    assert res.valid and res.status == "ok" and "silhouette" in res.timings_ms
    assert res.decided_by == "outline"
    assert np.isfinite(res.outline_chamfer_px) and res.outline_chamfer_px < 2.0
    assert abs(abs(res.R[2, 2]) - 1.0) < 0.05 and abs(res.t[2] - 9.0) < 0.5    # the plate, facing the camera
    # the plate's flip about z is the plate again: no margin, so demanding one leaves the frame undecided
    strict = _estimator(tmp_path / "s", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 5.0})
    res = strict.estimate(left, right)
    assert not res.valid and res.status == "weak_votes" and "the outline does not decide" in res.detail
    assert res.decided_by == ""
    assert np.isfinite(res.outline_margin_px) and res.outline_margin_px < 5.0


def _with_outline_chamfer(est, chamfer_px):
    """``est`` with its outline decision's best fit given ``chamfer_px`` (the synthetic plate fits exactly)."""
    real_outline = est._outline

    def outline(*args, **kwargs):
        d = real_outline(*args, **kwargs)
        return dataclasses.replace(d, best=dataclasses.replace(d.best, chamfer_px=chamfer_px))

    est._outline = outline
    return est


def test_a_loose_outline_moves_the_registered_position_when_the_bundle_asks(tmp_path, monkeypatch):
    """With ``registration.position_lateral`` a position-only frame whose outline fits loosely reports the
    registered centre moved by :func:`align_centroid`; without it, or where the outline fits, it is not moved."""
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()
    calls = []
    real = estimator_module.align_centroid

    def spy(R, t, *args):
        shifted = real(R, t, *args)
        calls.append((np.array(t), shifted))
        return None if shifted is None else shifted + np.array([0.1, 0.0, 0.0])

    monkeypatch.setattr(estimator_module, "align_centroid", spy)

    def estimator(name, lateral, chamfer_px):
        est = _estimator(tmp_path / name, {"min_margin": 0.99, "position_max_tau_m": 5.0, "position_lateral": lateral},
                         {"max_chamfer_px": 1.5, "min_margin_px": 5.0})
        return _with_outline_chamfer(est, chamfer_px).estimate(left, right)

    plain = estimator("p", 0, 3.0)
    assert plain.status == "weak_votes" and plain.position_valid and not calls
    moved = estimator("m", 1, 3.0)
    assert moved.status == "weak_votes" and moved.position_valid and len(calls) == 1
    t_reg, shifted = calls[0]
    assert shifted is not None and shifted[2] == t_reg[2]
    # the registered centre, moved by the centroid's shift (and the spy's 0.1 m)
    np.testing.assert_allclose(moved.position - plain.position, shifted - t_reg + [0.1, 0.0, 0.0], atol=1e-9)
    calls.clear()
    fits = estimator("f", 1, 1.0)
    assert fits.status == "weak_votes" and fits.position_valid and not calls   # the outline's fit is used as it is


def test_a_badly_fitting_outline_gives_no_position_when_the_bundle_gates_it(tmp_path):
    """``registration.position_max_chamfer_px``: a position-only frame whose outline's best fit is looser than
    the gate reports no position; within it, or with the gate off (0), it does."""
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()

    def estimate(name, gate, chamfer_px):
        est = _estimator(tmp_path / name, {"min_margin": 0.99, "position_max_tau_m": 5.0,
                                           "position_max_chamfer_px": gate},
                         {"max_chamfer_px": 1.5, "min_margin_px": 5.0})
        return _with_outline_chamfer(est, chamfer_px).estimate(left, right)

    for name, gate, chamfer, expected in (("in", 3.0, 2.9, True), ("out", 3.0, 3.1, False), ("off", 0.0, 9.0, True)):
        res = estimate(name, gate, chamfer)
        assert res.status == "weak_votes" and not res.valid
        assert res.position_valid is expected and bool(np.all(np.isfinite(res.position))) is expected, name


def test_the_position_range_bias_moves_a_position_only_frame_towards_the_camera(tmp_path):
    """``registration.position_range_bias_outline`` / ``..._registered``: a position-only frame's position moves
    nearer along its line of sight by that many depth tolerances, by the key of the source it came from (the
    outline's best fit when it fits within ``silhouette.max_chamfer_px``, else the registered pose)."""
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()

    def estimate(name, chamfer_px, outline_bias, registered_bias):
        est = _estimator(tmp_path / name, {"min_margin": 0.99, "position_max_tau_m": 5.0,
                                           "position_range_bias_outline": outline_bias,
                                           "position_range_bias_registered": registered_bias},
                         {"max_chamfer_px": 1.5, "min_margin_px": 5.0})
        return _with_outline_chamfer(est, chamfer_px).estimate(left, right)

    for chamfer, source in ((1.0, "outline"), (3.0, "registered")):
        plain = estimate(f"p{source}", chamfer, 0.0, 0.0)
        assert plain.status == "weak_votes" and plain.position_valid and plain.depth_tolerance_m > 0.0
        biases = {"outline": (0.3, 0.0), "registered": (0.0, 0.3)}[source]
        moved = estimate(f"m{source}", chamfer, *biases)
        other = estimate(f"o{source}", chamfer, *biases[::-1])      # the other source's key: not moved
        assert moved.status == "weak_votes" and moved.position_valid and not moved.valid
        r0, r1 = np.linalg.norm(plain.position), np.linalg.norm(moved.position)
        np.testing.assert_allclose(r0 - r1, 0.3 * plain.depth_tolerance_m, rtol=1e-9)
        np.testing.assert_allclose(moved.position / r1, plain.position / r0, atol=1e-12)   # along the line of sight
        np.testing.assert_array_equal(other.position, plain.position)
        np.testing.assert_array_equal(moved.R, plain.R)


def test_range_debiased_moves_along_the_line_of_sight_and_never_past_the_camera():
    from spacepose.registration import range_debiased

    p = np.array([3.0, 4.0, 12.0])                                  # range 13
    np.testing.assert_allclose(range_debiased(p, 0.5, 0.2), p * 12.9 / 13.0)
    np.testing.assert_array_equal(range_debiased(p, 0.5, 0.0), p)
    assert range_debiased(p, 0.5, 0.0) is not p                     # a copy: the caller's array is not aliased
    np.testing.assert_array_equal(range_debiased(p, 1e3, 0.5), np.zeros(3))
    np.testing.assert_array_equal(range_debiased(p, float("nan"), 0.2), p)
    nan = np.array([np.nan, 0.0, 1.0])
    assert np.isnan(range_debiased(nan, 0.5, 0.2)[0])
    with pytest.raises(ShapeError):
        range_debiased(np.zeros(2), 0.5, 0.2)


def test_the_estimator_searches_the_outline_when_the_bundle_asks(tmp_path):
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()
    plain = _estimator(tmp_path / "p", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0})
    assert plain._outline_templates is None
    est = _estimator(tmp_path / "s", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0,
                                                           "search_candidates": 2, "search_views": 200,
                                                           "points_weight": 1.0})
    assert est._outline_templates is not None and len(est._outline_templates.vectors) == 200
    res = est.estimate(left, right)
    assert res.valid and res.outline_chamfer_px < 2.0
    assert abs(abs(res.R[2, 2]) - 1.0) < 0.05 and abs(res.t[2] - 9.0) < 0.5    # the plate, facing the camera


def test_the_estimator_reports_the_polished_pose_when_asked(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair

    left, right = synthetic_pair()
    gates = {"max_chamfer_px": 100.0, "min_margin_px": 0.0}
    plain = _estimator(tmp_path / "p", {"min_margin": 0.99}, gates).estimate(left, right)
    assert plain.valid and np.isnan(plain.polish_deg) and np.isnan(plain.polish_m)
    calls = []
    real = estimator_module.polish_pose

    def spy(decision, R, t, *args, **kwargs):
        calls.append((np.array(R), np.array(t)))
        return real(decision, R, t, *args, **kwargs)

    monkeypatch.setattr(estimator_module, "polish_pose", spy)
    res = _estimator(tmp_path / "q", {"min_margin": 0.99}, dict(gates, polish=1)).estimate(left, right)
    assert res.valid and len(calls) == 1
    np.testing.assert_allclose(calls[0][0], plain.R, atol=1e-12)        # it starts from the decided pose
    assert np.isfinite(res.polish_deg) and res.polish_deg < 15.0 and res.polish_m < 1.0
    assert rotation_angle_deg(res.R, calls[0][0]) == pytest.approx(res.polish_deg, abs=1e-9)
    np.testing.assert_array_equal(res.decided[0], calls[0][0])   # the next frame tracks from the decided pose
    assert plain.decided is None


def test_the_estimator_refuses_a_pose_the_outline_and_the_points_disagree_on(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from spacepose.silhouette import OutlineDecision, OutlineFit

    left, right = synthetic_pair()
    est = _estimator(tmp_path, {"min_margin": 0.0}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0})
    chosen = {}

    def opposite(candidates, *args, **kwargs):
        R, t = candidates[0]
        R_f, t_f = flipped_pose(R, t, est.bundle.centre, "z")
        chosen["R"] = R_f
        return OutlineDecision(best=OutlineFit(R_f, t_f, 0.5), other=OutlineFit(R, t, 2.0), best_index=1,
                               margin_px=1.5, turned_deg=180.0)

    monkeypatch.setattr(estimator_module, "decide_outline", opposite)
    res = est.estimate(left, right)
    assert not res.valid and res.status == "weak_votes" and "opposite poses" in res.detail
    # without the registration's own decision, the outline's is the answer
    est2 = _estimator(tmp_path / "o", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0})
    res = est2.estimate(left, right)
    assert res.valid and rotation_angle_deg(res.R, chosen["R"]) < 1e-9 and res.outline_margin_px == 1.5


def test_a_tracked_frame_reports_the_outline_refined_pose_and_falls_back_when_it_fails_the_checks(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from spacepose.silhouette import OutlineDecision, OutlineFit

    left, right = synthetic_pair()
    first = _estimator(tmp_path / "l", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0}
                       ).estimate(left, right)
    assert first.valid
    # the outline never decides (margin 5 px demanded), nor does the registration: only tracking can
    est = _estimator(tmp_path / "t", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 5.0})
    est._prior = first
    est._roi_hint = lambda: None          # the coarse pass (the tiny bundle's prior window spans the frame)
    nudged = Rotation.from_euler("x", 2.0, degrees=True).as_matrix() @ first.R
    far = flipped_pose(first.R, first.t, est.bundle.centre, "z")

    def refined(candidates, *args, **kwargs):
        return OutlineDecision(best=OutlineFit(far[0], far[1], 0.8), other=OutlineFit(nudged, first.t, 0.9),
                               best_index=0, margin_px=0.1, turned_deg=178.0)

    monkeypatch.setattr(estimator_module, "decide_outline", refined)
    res = est.estimate(left, right)
    assert res.valid and res.tracked and res.decided_by == "tracked"
    assert rotation_angle_deg(res.R, nudged) < 1e-9           # the refined pose on the prior's side
    # the checks refuse the refined pose: the registered candidate it came from is reported instead
    original = est._verify
    monkeypatch.setattr(est, "_verify", lambda stage, *a: ("fit_residual", "stub") if
                        rotation_angle_deg(stage.R, nudged) < 1e-9 else original(stage, *a))
    res = est.estimate(left, right)
    assert res.valid and res.tracked and rotation_angle_deg(res.R, nudged) > 0.1
    assert rotation_angle_deg(res.R, first.R) < 20.0


@pytest.mark.parametrize("needs_outline", [0, 1])
def test_track_needs_outline_refuses_a_tracked_pose_no_outline_fit_confirms(tmp_path, monkeypatch, needs_outline):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from spacepose.silhouette import OutlineDecision, OutlineFit

    left, right = synthetic_pair()
    first = _estimator(tmp_path / "l", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0}
                       ).estimate(left, right)
    assert first.valid
    gates = {"max_chamfer_px": 1.0, "min_margin_px": 5.0, "track_needs_outline": needs_outline}
    est = _estimator(tmp_path / "t", {"min_margin": 0.99}, gates)
    assert est.bundle.silhouette.track_needs_outline == needs_outline
    est._roi_hint = lambda: None
    nudged = Rotation.from_euler("x", 2.0, degrees=True).as_matrix() @ first.R
    far = flipped_pose(first.R, first.t, est.bundle.centre, "z")
    fits = {"near": 3.0}      # the fit near the prior: outside the 1 px gate, then inside it

    def refined(candidates, *args, **kwargs):
        return OutlineDecision(best=OutlineFit(far[0], far[1], 0.8), other=OutlineFit(nudged, first.t, fits["near"]),
                               best_index=0, margin_px=0.1, turned_deg=178.0)

    monkeypatch.setattr(estimator_module, "decide_outline", refined)
    est._prior = first
    res = est.estimate(left, right)
    if needs_outline:   # no outline fit near the prior within the gate: the registered pose alone is not enough
        assert not res.valid and res.status == "weak_votes" and "near the previous pose" in res.detail
    else:               # the registered pose near the prior is reported
        assert res.valid and res.tracked and rotation_angle_deg(res.R, first.R) < 20.0
        assert rotation_angle_deg(res.R, nudged) > 0.1
    fits["near"] = 0.9
    est._prior = first
    res = est.estimate(left, right)
    assert res.valid and res.tracked and rotation_angle_deg(res.R, nudged) < 1e-9
    # the checks refuse the refined pose: the registered one is the fallback only without the flag
    original = est._verify
    monkeypatch.setattr(est, "_verify", lambda stage, *a: ("fit_residual", "stub") if
                        rotation_angle_deg(stage.R, nudged) < 1e-9 else original(stage, *a))
    est._prior = first
    res = est.estimate(left, right)
    assert res.valid != bool(needs_outline)
    if not needs_outline:
        assert res.tracked and rotation_angle_deg(res.R, nudged) > 0.1


@pytest.mark.parametrize("track_gate, tracked", [(0.0, False), (2.0, False), (3.0, True)])
def test_track_max_chamfer_px_loosens_only_the_tracking_routes_gate(tmp_path, monkeypatch, track_gate, tracked):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from spacepose.silhouette import OutlineDecision, OutlineFit

    left, right = synthetic_pair()
    first = _estimator(tmp_path / "l", {"min_margin": 0.99}, {"max_chamfer_px": 100.0, "min_margin_px": 0.0}
                       ).estimate(left, right)
    assert first.valid
    gates = {"max_chamfer_px": 1.0, "min_margin_px": 5.0, "track_needs_outline": 1,
             "track_max_chamfer_px": track_gate}
    est = _estimator(tmp_path / "t", {"min_margin": 0.99}, gates)
    assert est.bundle.silhouette.track_max_chamfer_px == track_gate
    est._roi_hint = lambda: None
    nudged = Rotation.from_euler("x", 2.0, degrees=True).as_matrix() @ first.R
    far = flipped_pose(first.R, first.t, est.bundle.centre, "z")

    def refined(candidates, *args, **kwargs):   # the fit near the prior at 2.5 px: outside 1 and 2, inside 3
        return OutlineDecision(best=OutlineFit(far[0], far[1], 2.4), other=OutlineFit(nudged, first.t, 2.5),
                               best_index=0, margin_px=0.1, turned_deg=178.0)

    monkeypatch.setattr(estimator_module, "decide_outline", refined)
    est._prior = first
    res = est.estimate(left, right)
    assert res.valid == tracked
    if tracked:    # the fit near the prior, never the better-fitting flip
        assert res.tracked and rotation_angle_deg(res.R, nudged) < 1e-9
    else:
        assert res.status == "weak_votes" and "near the previous pose" in res.detail
    # without a prior the looser gate decides nothing
    est.reset()
    res = est.estimate(left, right)
    assert not res.valid and res.status == "weak_votes"


@pytest.mark.parametrize("bad", [-0.5, float("nan")])
def test_track_max_chamfer_px_must_not_be_negative(bad):
    with pytest.raises(ValueError):
        SilhouetteConfig(track_max_chamfer_px=bad)
    assert SilhouetteConfig().track_max_chamfer_px == 0.0


def test_track_needs_outline_is_a_flag():
    with pytest.raises(ValueError):
        SilhouetteConfig(track_needs_outline=2)
    assert SilhouetteConfig().track_needs_outline == 0


def test_points_behind_the_camera_or_a_nan_pose_splat_nothing(plate):
    pts, _ = plate
    frame = silhouette_frame(K, 160, 80, 320, 192)
    mask, _, inside = splat_mask(pts, np.eye(3), np.array([0.0, 0.0, -20.0]), frame)
    assert not inside.any() and mask.sum() == 0
    mask, _, inside = splat_mask(pts, np.full((3, 3), np.nan), np.zeros(3), frame)
    assert not inside.any() and mask.sum() == 0
    # a point a hair in front of the camera lands far outside, not wrapped back into the frame
    mask, _, inside = splat_mask(np.array([[1.0, 1.0, 1e-5]]), np.eye(3), np.zeros(3), frame)
    assert not inside.any()


def test_a_registration_decision_the_outline_leans_against_is_not_reported(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from spacepose.silhouette import OutlineDecision, OutlineFit

    left, right = synthetic_pair()
    # the registration decides (min_margin 0) and the outline does not (a 5 px margin demanded)
    est = _estimator(tmp_path, {"min_margin": 0.0}, {"max_chamfer_px": 100.0, "min_margin_px": 5.0})
    decided = est.estimate(left, right)
    assert decided.valid and decided.decided_by == "registration"

    def leaning(candidates, *args, **kwargs):   # undecided, but its best fit is the flip
        R, t = candidates[0]
        R_f, t_f = flipped_pose(R, t, est.bundle.centre, "z")
        return OutlineDecision(best=OutlineFit(R_f, t_f, 0.9), other=OutlineFit(R, t, 1.0), best_index=1,
                               margin_px=0.1, turned_deg=180.0)

    monkeypatch.setattr(estimator_module, "decide_outline", leaning)
    est.reset()
    res = est.estimate(left, right)
    assert not res.valid and res.status == "weak_votes" and "leans to its flip" in res.detail


def test_a_registration_decision_the_image_vetoes_is_not_reported(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from spacepose.image_vote import ImageVote
    from spacepose.silhouette import OutlineDecision, OutlineFit

    left, right = synthetic_pair()
    # the registration decides (min_margin 0), the outline does not (a 5 px margin demanded) but agrees
    est = _estimator(tmp_path, {"min_margin": 0.0},
                     {"max_chamfer_px": 100.0, "min_margin_px": 5.0, "image_vote": 1, "image_veto_score": 0.0})

    def agreeing(score):
        def decide(candidates, *args, **kwargs):
            R, t = candidates[0]
            R_f, t_f = flipped_pose(R, t, est.bundle.centre, "z")
            return OutlineDecision(best=OutlineFit(R, t, 0.9), other=OutlineFit(R_f, t_f, 1.0), best_index=0,
                                   margin_px=0.1, turned_deg=180.0, vote=ImageVote(score, 200, 0.0, 0.1, True))
        return decide

    monkeypatch.setattr(estimator_module, "decide_outline", agreeing(0.05))
    assert est.estimate(left, right).valid
    monkeypatch.setattr(estimator_module, "decide_outline", agreeing(0.0))   # the image does not back it
    est.reset()
    res = est.estimate(left, right)
    assert not res.valid and res.status == "weak_votes" and "image does not back it" in res.detail
