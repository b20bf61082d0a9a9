import numpy as np
import pytest

torch = pytest.importorskip("torch")

from spacepose.errors import DatasetError  # noqa: E402
from spacepose.tools.stereo_data import StereoCropConfig, StereoCropDataset, read_labels  # noqa: E402


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
