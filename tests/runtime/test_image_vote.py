"""Tests of spacepose.image_vote and of the image route of the silhouette stage's decision."""

import dataclasses
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers

from spacepose.errors import ShapeError  # noqa: E402
from spacepose.flip import flipped_pose  # noqa: E402
from spacepose.registration import rotation_angle_deg  # noqa: E402
from spacepose.image_vote import ImageVote, crop_to_frame, grey_unit, image_vote, window_grey  # noqa: E402
from spacepose.silhouette import (OutlineDecision, OutlineFit, SilhouetteConfig, decide_outline,  # noqa: E402
                                  silhouette_frame, splat_mask)

N = 128


def _disc(cx, cy, r, n=N):
    m = np.zeros((n, n), np.uint8)
    cv2.circle(m, (cx, cy), r, 1, -1)
    return m


def _body_with_dish(side):
    """A body disc with a small dish disc on the ``side`` (+1 right, -1 left): a pose and its flip."""
    return np.maximum(_disc(64, 64, 30), _disc(64 + side * 42, 64, 9))


def _lit(mask, level=0.8, sky=0.01, noise=0.005, seed=0):
    rng = np.random.default_rng(seed)
    return np.clip(np.where(mask > 0, level, sky) + rng.normal(0, noise, mask.shape), 0, 1).astype(np.float32)


def test_lit_pixels_vote_for_the_outline_that_covers_them():
    right, left = _body_with_dish(+1), _body_with_dish(-1)
    grey = _lit(right)
    vote = image_vote(grey, right, left)
    assert vote.usable and vote.score > 0.4 and vote.pixels > 300
    back = image_vote(grey, left, right)       # the same evidence, read for the other pose
    assert back.usable and back.score == pytest.approx(-vote.score) and back.pixels == vote.pixels


def test_an_unlit_part_abstains_rather_than_votes():
    right, left = _body_with_dish(+1), _body_with_dish(-1)
    grey = _lit(_disc(64, 64, 30))             # the dish is in shadow: as dark as the sky
    vote = image_vote(grey, right, left)
    assert vote.usable and abs(vote.score) < 0.02


def test_a_lit_sky_around_the_target_makes_the_vote_unusable():
    right, left = _body_with_dish(+1), _body_with_dish(-1)
    grey = _lit(right)
    grey[:, :40] = 0.5                          # the Earth behind the left half of the window
    vote = image_vote(grey, right, left)
    assert not vote.usable and vote.background_lit > 0.02


def test_the_vote_does_not_depend_on_exposure_or_sky_level():
    right, left = _body_with_dish(+1), _body_with_dish(-1)
    base = image_vote(_lit(right), right, left)
    dim = image_vote(0.05 + 0.3 * _lit(right), right, left)
    assert dim.usable and dim.score == pytest.approx(base.score)


def test_outlines_a_blur_apart_do_not_vote():
    a = _disc(64, 64, 30)
    b = np.roll(a, 1, axis=1)                   # one pixel apart: inside the exclusion band
    vote = image_vote(_lit(a), a, b, exclusion_px=2)
    assert vote.pixels == 0 and vote.score == 0.0 and not vote.usable
    assert image_vote(_lit(a), a, b, exclusion_px=0).pixels > 0
    right, left = _body_with_dish(+1), _body_with_dish(-1)
    few = image_vote(_lit(right), right, left, min_pixels=10_000)   # too few differing pixels to count on
    assert not few.usable and few.score > 0.4
    empty = image_vote(_lit(a), np.zeros_like(a), np.zeros_like(a))
    assert not empty.usable and empty.pixels == 0


def test_shapes_are_checked():
    a = _disc(64, 64, 30)
    with pytest.raises(ShapeError):
        image_vote(np.zeros((N, N + 1), np.float32), a, a)
    with pytest.raises(ShapeError):
        image_vote(_lit(a), a, a[:-1])
    with pytest.raises(ValueError):
        image_vote(_lit(a), a, a, ring_px=(5, 3))
    with pytest.raises(ValueError):
        grey_unit(np.zeros((4, 4, 2), np.uint8))


def test_grey_unit_scales_by_dtype_and_averages_channels():
    assert grey_unit(np.full((2, 2), 255, np.uint8)).max() == pytest.approx(1.0)
    assert grey_unit(np.full((2, 2), 65535, np.uint16)).max() == pytest.approx(1.0)
    colour = np.zeros((2, 2, 3), np.uint8)
    colour[..., 0] = 255
    assert grey_unit(colour)[0, 0] == pytest.approx(1.0 / 3.0)
    assert grey_unit(np.full((2, 2), 127.5, np.float32))[0, 0] == pytest.approx(0.5)


@pytest.mark.parametrize("dtype, full", [(np.uint8, 255.0), (np.uint16, 65535.0), (np.float32, 255.0)])
def test_grey_unit_of_colour_equals_the_channel_mean_bit_for_bit(dtype, full):
    rng = np.random.default_rng(7)
    colour = (rng.uniform(0, full + 1, (31, 17, 3)) // (1 if dtype != np.float32 else 0.001)).astype(dtype)
    ref = colour.astype(np.float32).mean(axis=2) / np.float32(full)
    np.testing.assert_array_equal(grey_unit(colour), ref)
    np.testing.assert_array_equal(grey_unit(np.dstack([colour, colour[..., :1]])), ref)   # alpha dropped


def test_window_grey_crops_pads_and_resamples_like_opencv():
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    inside = window_grey(image, 8, 4, 32, 16)
    ref = cv2.resize(image[4:36, 8:40].astype(np.float32).mean(axis=2) / 255.0, (16, 16),
                     interpolation=cv2.INTER_AREA)
    np.testing.assert_allclose(inside, ref, atol=1e-5)
    edge = window_grey(image, -10, -6, 20, 20)   # hangs off the top-left corner: zero there
    assert np.all(edge[:6, :] == 0) and np.all(edge[:, :10] == 0)
    np.testing.assert_allclose(edge[6:, 10:], image[:14, :10].astype(np.float32).mean(axis=2) / 255.0, atol=1e-6)
    assert np.all(window_grey(image, 100, 100, 10, 10) == 0)
    np.testing.assert_allclose(crop_to_frame(np.ones((4, 4), np.float32), -2, -2, 4, 4)[2:, 2:], 1.0)


def _decision(margin, vote, chamfer=1.0):
    R, t = np.eye(3), np.array([0.0, 0.0, 20.0])
    return OutlineDecision(best=OutlineFit(R, t, chamfer), other=OutlineFit(-R, t, chamfer + margin), best_index=0,
                           margin_px=margin, turned_deg=180.0, vote=vote)


@pytest.mark.parametrize("margin, vote, image_on, chamfer, decided", [
    (0.6, None, 0, 1.0, True),                                        # the margin alone
    (0.3, ImageVote(0.3, 400, 0.0, 0.1, True), 0, 1.0, False),       # image route off
    (0.3, ImageVote(0.3, 400, 0.0, 0.1, True), 1, 1.0, True),        # image route on
    (0.3, ImageVote(0.05, 400, 0.0, 0.1, True), 1, 1.0, False),      # too weak a vote
    (0.3, ImageVote(0.3, 400, 0.2, 0.1, False), 1, 1.0, False),      # lit sky: no vote
    (0.1, ImageVote(0.3, 400, 0.0, 0.1, True), 1, 1.0, False),       # too small a margin even for the image
    (0.3, ImageVote(0.3, 400, 0.0, 0.1, True), 1, 2.0, False),       # the outline does not fit
    (0.3, None, 1, 1.0, False),                                       # no vote taken
    (0.9, ImageVote(-0.3, 400, 0.0, 0.1, True), 1, 1.0, False),      # a large margin the image refutes
    (0.9, ImageVote(-0.3, 400, 0.0, 0.1, True), 0, 1.0, True),       # ... unless the image route is off
    (0.9, ImageVote(-0.3, 4, 0.0, 0.1, False), 1, 1.0, True),        # ... or the vote is not usable
    (0.9, ImageVote(-0.05, 400, 0.0, 0.1, True), 1, 1.0, True),      # a weak vote against does not veto
    (0.9, ImageVote(-0.1, 400, 0.0, 0.1, True), 1, 1.0, False),      # the veto includes its bound
])
def test_the_decision_takes_the_image_route_only_when_asked_and_backed(margin, vote, image_on, chamfer, decided):
    config = SilhouetteConfig(max_chamfer_px=1.5, min_margin_px=0.5, image_vote=image_on, image_min_score=0.1,
                              image_min_margin_px=0.2)
    assert _decision(margin, vote, chamfer).decided(config) is decided


@pytest.mark.parametrize("score, usable, decided", [
    (0.0, True, False),      # all the differing pixels dark: the margin is not trusted
    (-0.05, True, False),    # a weak lean to the flip
    (0.02, True, True),      # a weak lean to the winner
    (0.0, False, True),      # no usable vote: the margin alone
])
def test_a_veto_score_of_zero_asks_the_image_to_lean_to_the_winner(score, usable, decided):
    config = SilhouetteConfig(max_chamfer_px=1.5, min_margin_px=0.5, image_vote=1, image_veto_score=0.0)
    assert _decision(0.9, ImageVote(score, 400, 0.0, 0.1, usable), 1.0).decided(config) is decided


@pytest.mark.parametrize("chamfer, margin, score, decided", [
    (1.8, 0.3, 0.3, True),       # a looser fit the image backs
    (1.8, 0.9, 0.05, False),     # ... but the margin route keeps its own chamfer gate
    (2.2, 0.3, 0.3, False),      # beyond the image route's gate
    (1.8, 0.1, 0.3, False),      # too small a margin
])
def test_the_image_route_has_its_own_chamfer_gate(chamfer, margin, score, decided):
    config = SilhouetteConfig(max_chamfer_px=1.5, min_margin_px=0.5, image_vote=1, image_min_margin_px=0.2,
                              image_max_chamfer_px=2.0)
    assert _decision(margin, ImageVote(score, 400, 0.0, 0.1, True), chamfer).decided(config) is decided
    # without it (0, the default) the image route keeps max_chamfer_px
    plain = SilhouetteConfig(max_chamfer_px=1.5, min_margin_px=0.5, image_vote=1, image_min_margin_px=0.2)
    assert not _decision(margin, ImageVote(score, 400, 0.0, 0.1, True), chamfer).decided(plain)


@pytest.mark.parametrize("pixels, image_on, decided", [
    (7, 1, False),      # pose and flip differ in 7 px: the outline cannot tell them apart
    (16, 1, True),
    (7, 0, True),       # without the image vote nothing is counted
])
def test_min_flip_pixels_refuses_a_margin_the_flip_cannot_show(pixels, image_on, decided):
    config = SilhouetteConfig(max_chamfer_px=1.5, min_margin_px=0.5, image_vote=image_on, min_flip_pixels=16)
    dec = _decision(0.9, ImageVote(0.0, pixels, 0.0, 0.1, False), 1.0)
    assert dec.decided(config) is decided
    assert _decision(0.9, None, 1.0).decided(config)    # no vote taken: nothing counted, the margin decides


def test_config_refuses_bad_image_settings():
    for bad in ({"image_vote": 2}, {"image_exclusion_px": -1}, {"image_max_background": 1.5},
                {"image_min_pixels": -1}, {"image_veto_score": 0.1}, {"image_veto_score": -1.5},
                {"image_min_score": 0.05, "image_veto_score": 0.05}, {"image_max_chamfer_px": -1.0},
                {"min_flip_pixels": -1}):
        with pytest.raises(ValueError):
            SilhouetteConfig(**bad)


def _tab_plate(rng):
    """Samples of a 4 x 2 m plate with a 1 x 0.8 m tab on one short side (flat, z = 0)."""
    plate = np.column_stack([rng.uniform(-2, 2, 20000), rng.uniform(-1, 1, 20000), np.zeros(20000)])
    tab = np.column_stack([rng.uniform(2, 3, 4000), rng.uniform(0.1, 0.9, 4000), np.zeros(4000)])
    return np.vstack([plate, tab])


def test_decide_outline_votes_with_the_image_and_only_when_asked():
    K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])
    pts = _tab_plate(np.random.default_rng(0))
    R = Rotation.from_euler("xyz", (10, -5, 30), degrees=True).as_matrix()
    t = np.array([0.2, -0.1, 25.0])
    full = silhouette_frame(K, 0, 0, 640, 640)
    mask = splat_mask(pts, R, t, full)[0][:480, :640]
    disparity = np.where(mask > 0, K[0, 0] / t[2], 0.0).astype(np.float32)
    image = np.where(mask > 0, 200, 3).astype(np.uint8)
    flip = (lambda R_, t_: flipped_pose(R_, t_, np.zeros(3), "z"))
    window = (320 - 120, 240 - 120, 240)
    config = SilhouetteConfig(max_chamfer_px=5.0, min_margin_px=100.0, image_vote=1)
    dec = decide_outline([(R, t)], pts, disparity, K, 1.0, window, config, flip=flip, image=image)
    assert float(rotation_angle_deg(dec.best.R, R)) < 3.0
    assert dec.vote is not None and dec.vote.usable and dec.vote.score > 0.3
    assert dec.decided(config) and not dec.decided(SilhouetteConfig(max_chamfer_px=5.0, min_margin_px=100.0))
    # the same frame with the image vote off, or no image: no vote
    assert decide_outline([(R, t)], pts, disparity, K, 1.0, window, SilhouetteConfig(), flip=flip,
                          image=image).vote is None
    assert decide_outline([(R, t)], pts, disparity, K, 1.0, window, config, flip=flip).vote is None
    # the image showing the flip instead: the vote goes against the outline's winner
    R_f, t_f = flip(R, t)
    flipped = np.where(splat_mask(pts, R_f, t_f, full)[0][:480, :640] > 0, 200, 3).astype(np.uint8)
    against = decide_outline([(R, t)], pts, disparity, K, 1.0, window, config, flip=flip, image=flipped)
    assert against.vote.score < -0.3 and not against.decided(config)



def test_the_estimator_gives_the_left_image_to_the_vote_and_reports_it(tmp_path, monkeypatch):
    import spacepose.estimator as estimator_module
    from _bundle_fixtures import synthetic_pair
    from test_silhouette import _estimator

    left, right = synthetic_pair()
    est = _estimator(tmp_path, {"min_margin": 0.99},
                     {"max_chamfer_px": 100.0, "min_margin_px": 5.0, "image_vote": 1, "image_min_margin_px": 0.2,
                      "image_min_score": 0.1})
    seen = {}

    def decide(candidates, *args, image=None, **kwargs):
        seen["image"] = image
        R, t = candidates[0]
        R_f, t_f = flipped_pose(R, t, est.bundle.centre, "z")
        return OutlineDecision(best=OutlineFit(R, t, 0.8), other=OutlineFit(R_f, t_f, 1.1), best_index=0,
                               margin_px=0.3, turned_deg=180.0, vote=ImageVote(0.25, 500, 0.0, 0.1, True))

    monkeypatch.setattr(estimator_module, "decide_outline", decide)
    res = est.estimate(left, right)
    assert seen["image"] is not None and seen["image"].shape[:2] == left.shape[:2]
    assert res.valid and res.outline_image_score == 0.25 and res.outline_image_background == 0.0
    assert res.decided_by == "image"         # a 0.3 px margin: the margin route (5 px) would not decide
    assert 0.0 < res.confidence < 1.0
    # the same frame, the vote against it: undecided, and the reason names the outline
    monkeypatch.setattr(estimator_module, "decide_outline", lambda *a, **k: dataclasses.replace(
        decide(*a, **k), vote=ImageVote(-0.25, 500, 0.0, 0.1, True)))
    est.reset()   # without a prior: the previous pose would otherwise decide the frame (tracking)
    res = est.estimate(left, right)
    assert not res.valid and res.status == "weak_votes" and "outline does not decide" in res.detail
    assert res.outline_image_score == -0.25
