import json

import numpy as np
import pytest

from spacepose.tools.eval_stereo import (MetricAccumulator, SGBMParams, format_table, sgbm_disparity,  # noqa: E402
                                         sgbm_for_rig)


def test_accumulator_is_pixel_weighted():
    acc = MetricAccumulator()
    gt = np.full((4, 4), 10.0, np.float32)
    v1 = np.zeros((4, 4), bool)
    v1[0, 0] = True
    acc.add(gt + 4.0, gt, v1)  # 1 pixel, error 4
    acc.add(gt.copy(), gt, np.ones((4, 4), bool))  # 16 pixels, error 0
    r = acc.result()
    assert r["epe"] == pytest.approx(4.0 / 17) and r["rmse"] == pytest.approx(np.sqrt(16.0 / 17))
    assert r["bad3"] == pytest.approx(100 / 17) and r["d1"] == pytest.approx(100 / 17) and r["pixels"] == 17


def test_sgbm_on_shifted_texture():
    rng = np.random.default_rng(0)
    img = (rng.random((120, 200)) * 255).astype(np.uint8)
    right = np.roll(img, -12, axis=1)
    d = sgbm_disparity(img, right, SGBMParams(num_disparities=32))
    assert np.median(d[20:100, 60:180]) == pytest.approx(12.0, abs=0.5)
    assert sgbm_for_rig(800.0, 1.0).num_disparities == 96


def test_eval_cli(synthetic_dataset, tiny_bundle, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from spacepose.cli import main

    out = tmp_path / "eval"
    rc = main(["eval-stereo", str(synthetic_dataset), "--bundle", str(tiny_bundle), "--out", str(out), "--limit", "4",
               "--threads", "1"])
    assert rc == 0
    report = json.loads((out / "stereo_eval.json").read_text())
    assert report["frames"] == 4
    for name in ("ours", "sgbm"):
        groups = report[name]
        assert groups["overall"]["pixels"] > 0
        assert {g for g in groups if g.startswith("regime:")} == {"regime:sun", "regime:albedo", "regime:penumbra",
                                                                  "regime:mixed"}
        assert sum(groups[g]["pixels"] for g in groups if g.startswith("distance:")) == groups["overall"]["pixels"]
        regions = [g for g in groups if g.startswith("region:")]
        assert regions == ["region:interior", "region:silhouette"] and list(groups)[-2:] == regions
        assert sum(groups[g]["pixels"] for g in regions) == groups["overall"]["pixels"]
    assert (out / "stereo_fig13.png").stat().st_size > 1000
    assert "| overall | sgbm |" in format_table(report)
    assert report["sgbm_params"]["mode"] == "SGBM_3WAY"
    # per-frame rows: their pixel-weighted mean is the overall EPE (weights: target pixels per frame)
    rows = report["per_frame"]
    assert len(rows) == 4 and all(set(r["ours"]) == {"epe", "median", "zero_share"} for r in rows)
    assert all(0.0 <= r["sgbm"]["zero_share"] <= 1.0 and r["ours"]["median"] <= r["ours"]["epe"] * 10 + 1e-6 for r in rows)
    assert min(r["ours"]["epe"] for r in rows) <= report["ours"]["overall"]["epe"] <= max(r["ours"]["epe"] for r in rows)


def test_silhouette_band():
    from spacepose.tools.eval_stereo import silhouette_band

    valid = np.zeros((12, 12), bool)
    valid[2:10, 2:10] = True
    valid[0:3, 11] = True  # on the image border
    band = silhouette_band(valid, radius=2)
    assert not band[~valid].any()
    sq = band[2:10, 2:10]
    assert sq[:2].all() and sq[-2:].all() and sq[:, :2].all() and sq[:, -2:].all() and not sq[2:6, 2:6].any()
    full = np.ones((6, 6), bool)
    assert not silhouette_band(full, 1).any()  # the image border is not background


def test_silhouette_band_is_the_one_training_weighs():
    """eval-stereo's region:silhouette rows measure the band that train-stereo --edge-weight weighs."""
    torch = pytest.importorskip("torch")
    from spacepose.models.stereo_loss import silhouette_band as train_band
    from spacepose.tools.eval_stereo import SILHOUETTE_RADIUS, silhouette_band
    from spacepose.tools.train_stereo import TrainConfig

    assert TrainConfig(dataset="d", out="o").edge_radius == SILHOUETTE_RADIUS
    rng = np.random.default_rng(3)
    for radius in (1, SILHOUETTE_RADIUS):
        valid = rng.random((40, 50)) < 0.7
        want = train_band(torch.from_numpy(valid)[None, None], radius)[0, 0].numpy()
        np.testing.assert_array_equal(silhouette_band(valid, radius), want)
