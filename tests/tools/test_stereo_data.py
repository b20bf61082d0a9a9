import numpy as np
import pytest

torch = pytest.importorskip("torch")

from spacepose.errors import DatasetError  # noqa: E402
from spacepose.tools.stereo_data import (StereoCropConfig, StereoCropDataset, read_labels,  # noqa: E402
                                         sample_wide_look, wide_look)


def test_labels(synthetic_dataset):
    assert len(read_labels(synthetic_dataset, "train")) == 6
    test = read_labels(synthetic_dataset, "test")
    assert len(test) == 4 and all(10 <= r.distance_m <= 50 for r in test)
    with pytest.raises(DatasetError):
        StereoCropDataset(synthetic_dataset, "nosuchsplit")


def test_sample_contents_and_gt_scaling(synthetic_dataset):
    cfg = StereoCropConfig(size=(64, 64), augment=False)
    ds = StereoCropDataset(synthetic_dataset, "train", cfg, seed=3)
    kinds = set()
    for epoch in range(3):
        ds.set_epoch(epoch)
        for i in range(len(ds)):
            s = ds[i]
            kinds.add(s["kind"])
            assert s["left"].shape == (3, 64, 64) and s["disparity"].shape == (1, 64, 64)
            target = s["target"] > 0.5
            valid = (s["valid"] > 0.5) & target
            assert valid.any()
            # background is supervised at its true disparity 0 (at infinity)
            background = ~target
            assert torch.all(s["valid"][background] > 0.5) and torch.all(s["disparity"][background] == 0)
            # the synthetic plates have constant disparity: every valid GT pixel = d_frame * scale
            vals = s["disparity"][valid]
            assert torch.allclose(vals, vals[0].expand_as(vals))
            rec = ds.records[i]
            d_frame = round(float(vals[0]) / s["scale"])
            assert d_frame == pytest.approx(float(vals[0]) / s["scale"], abs=1e-3)
            assert s["regime"] == rec.regime
    assert kinds == {"roi", "letterbox"}


def test_roi_view_holds_target_in_both_images(synthetic_dataset):
    cfg = StereoCropConfig(size=(64, 64), augment=False, roi_prob=1.0)
    ds = StereoCropDataset(synthetic_dataset, "train", cfg, deterministic=True)
    s = ds[0]
    left, right = s["left"].numpy().mean(0), s["right"].numpy().mean(0)
    # target texture is visible in both views (right holds the shifted copy)
    assert (left > 15).mean() > 0.15 and (right > 15).mean() > 0.15
    assert s["kind"] == "roi"


def test_augmentation_is_deterministic_per_epoch_and_asymmetric(synthetic_dataset):
    ds = StereoCropDataset(synthetic_dataset, "train", StereoCropConfig(size=(64, 64)), seed=1)
    a, b = ds[2], ds[2]
    assert torch.equal(a["left"], b["left"])
    ds.set_epoch(1)
    c = ds[2]
    assert not torch.equal(a["left"], c["left"])
    assert float(a["left"].min()) >= 0 and float(a["left"].max()) <= 255


def test_train_crop_holds_target_and_keeps_disparity(synthetic_dataset):
    full = StereoCropDataset(synthetic_dataset, "train", StereoCropConfig(size=(64, 64), augment=False), seed=3)
    cropped = StereoCropDataset(synthetic_dataset, "train",
                                StereoCropConfig(size=(64, 64), augment=False, train_crop=(32, 32)), seed=3)
    for i in range(len(full)):
        a, b = full[i], cropped[i]
        assert b["left"].shape == (3, 32, 32) and b["disparity"].shape == (1, 32, 32)
        assert b["target"].sum() > 0  # the crop holds the target centre
        assert a["scale"] == b["scale"]
        # same GT values: a sub-crop does not rescale disparity
        assert set(b["disparity"][b["target"] > 0.5].unique().tolist()) <= set(a["disparity"].unique().tolist())


def test_oversample_repeats_a_regime(synthetic_dataset):
    from spacepose.tools.stereo_data import oversample_records

    records = read_labels(synthetic_dataset, "train")
    regime = records[0].regime
    more = oversample_records(records, {regime: 3})
    n = sum(r.regime == regime for r in records)
    assert len(more) == len(records) + 2 * n
    assert [r for r in more if r.regime != regime] == [r for r in records if r.regime != regime]
    ds = StereoCropDataset(synthetic_dataset, "train", StereoCropConfig(size=(64, 64)), oversample={regime: 2})
    assert len(ds) == len(records) + n
    with pytest.raises(DatasetError, match="no frames of regime"):
        oversample_records(records, {"nosuchregime": 2})
    with pytest.raises(ValueError):
        oversample_records(records, {regime: 0})


def test_wide_look_is_one_look_for_both_views_and_clips_like_an_exposure():
    rng = np.random.default_rng(0)
    image = rng.uniform(0, 255, size=(32, 40, 3)).astype(np.float32)
    look = {"gamma": 0.5, "tint": np.array([1.2, 1.0, 0.8], np.float32), "gain": 1.8, "blur_px": 0.0}
    a, b = wide_look(image, look), wide_look(image.copy(), look)
    assert a.shape == image.shape and a.dtype == np.float32
    assert np.array_equal(a, b)
    assert float(a.min()) >= 0.0 and float(a.max()) <= 255.0
    expect = np.clip((image / 255.0) ** 0.5 * look["tint"] * 1.8, 0.0, 1.0) * 255.0
    np.testing.assert_allclose(a, expect, atol=1e-3)
    assert (a[..., 0] >= 254.99).mean() > 0.5                     # the exposure pushes most of red past white
    blurred = wide_look(image, {**look, "gain": 0.5, "blur_px": 1.5})
    assert np.abs(np.diff(blurred, axis=1)).mean() < 0.5 * np.abs(np.diff(wide_look(image, {**look, "gain": 0.5}),
                                                                           axis=1)).mean()
    with pytest.raises(DatasetError):
        wide_look(image[..., 0], look)


def test_sample_wide_look_ranges():
    rng = np.random.default_rng(3)
    looks = [sample_wide_look(rng) for _ in range(400)]
    gammas = np.array([lk["gamma"] for lk in looks])
    assert 0.4 <= gammas.min() < 0.5 and 2.0 < gammas.max() <= 2.5
    assert all(0.5 <= lk["gain"] <= 1.8 and 0.0 <= lk["blur_px"] <= 1.5 for lk in looks)
    assert all(np.all((lk["tint"] >= 0.75) & (lk["tint"] <= 1.25)) for lk in looks)


def test_wide_photometric_changes_samples_and_mild_is_the_default(synthetic_dataset):
    assert StereoCropConfig().photometric == "mild"
    with pytest.raises(ValueError, match="photometric"):
        StereoCropConfig(photometric="loud")
    mild = StereoCropDataset(synthetic_dataset, "train", StereoCropConfig(size=(64, 64)), seed=1)
    wide = StereoCropDataset(synthetic_dataset, "train", StereoCropConfig(size=(64, 64), photometric="wide",
                                                                         wide_prob=1.0), seed=1)
    a, b = mild[2], wide[2]
    assert torch.equal(a["disparity"], b["disparity"])            # the look never moves the geometry
    assert not torch.equal(a["left"], b["left"])
    assert float(b["left"].min()) >= 0 and float(b["left"].max()) <= 255
    assert torch.equal(b["left"], wide[2]["left"])                # deterministic per epoch
