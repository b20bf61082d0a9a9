"""Tests of spacepose.infinity: pixels the images place at zero disparity."""

import cv2
import numpy as np
import pytest

from spacepose.infinity import infinity_mask, local_zncc

H, W = 96, 160


def _texture(seed, shape=(H, W)):
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), 1.0)


def _scene(target_disp=20):
    """Background texture at infinity (same in both views) with a textured box at ``target_disp``."""
    bg, tg = _texture(0), _texture(1)
    left, right = bg.copy(), bg.copy()
    y0, y1, x0, x1 = 30, 70, 80, 130
    left[y0:y1, x0:x1] = tg[y0:y1, x0:x1]
    right[y0:y1, x0 - target_disp:x1 - target_disp] = tg[y0:y1, x0:x1]
    box = np.zeros((H, W), bool)
    box[y0:y1, x0:x1] = True
    return left, right, box


def test_background_with_hallucinated_disparity_is_flagged_target_is_kept():
    left, right, box = _scene()
    disp = np.where(box, 20.0, 7.0).astype(np.float32)  # the graph put the background at 7 px
    mask = infinity_mask(left, right, disp)
    inner_bg = ~cv2.dilate(box.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    inner_bg[:, :12] = False  # the warped right view leaves the image there
    assert mask[inner_bg].mean() > 0.9
    inner_box = cv2.erode(box.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    assert mask[inner_box].mean() < 0.01


def test_pixels_at_or_below_min_disparity_and_flat_pixels_are_never_flagged():
    left, right, box = _scene()
    assert not infinity_mask(left, right, np.zeros((H, W), np.float32)).any()
    flat = np.full((H, W), 80.0, np.float32)
    assert not infinity_mask(flat, flat, np.full((H, W), 5.0, np.float32)).any()


def test_colour_and_nchw_inputs_and_shape_check():
    left, right, box = _scene()
    disp = np.where(box, 20.0, 7.0).astype(np.float32)
    ref = infinity_mask(left, right, disp)
    colour = [np.repeat(im[..., None], 3, axis=2) for im in (left, right)]
    np.testing.assert_array_equal(infinity_mask(*colour, disp), ref)
    nchw = [im.transpose(2, 0, 1)[None] for im in colour]
    np.testing.assert_array_equal(infinity_mask(*nchw, disp), ref)
    with pytest.raises(Exception):
        infinity_mask(left, right[:10], disp)


def test_local_zncc_matches_a_direct_computation():
    a, b = _texture(3, (20, 20)), _texture(4, (20, 20))
    z, std = local_zncc(a, b, window=5)
    pa, pb = a[5:10, 5:10] - a[5:10, 5:10].mean(), b[5:10, 5:10] - b[5:10, 5:10].mean()
    assert z[7, 7] == pytest.approx((pa * pb).mean() / (pa.std() * pb.std()), abs=1e-3)
    assert std[7, 7] == pytest.approx(pa.std(), rel=1e-3)


def test_regions_go_as_a_whole_target_region_stays():
    from spacepose.infinity import infinity_regions

    left, right, box = _scene()
    bg_region = np.zeros((H, W), bool)
    bg_region[5:25, 20:150] = True  # a background blob given 7 px, separate from the target
    disp = np.where(box, 20.0, np.where(bg_region, 7.0, 0.0)).astype(np.float32)
    regions = infinity_regions(left, right, disp)
    np.testing.assert_array_equal(regions, bg_region)  # the whole blob, edges included; the target kept
    assert not infinity_regions(left, right, np.where(box, 20.0, 0.0).astype(np.float32)).any()
