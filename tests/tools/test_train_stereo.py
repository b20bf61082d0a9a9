import dataclasses
import json
import shutil

import pytest

torch = pytest.importorskip("torch")

from spacepose.errors import SpaceposeError  # noqa: E402
from spacepose.tools.train_stereo import EpochSampler, TrainConfig, load_checkpoint, train_stereo  # noqa: E402

TINY = {"feature_widths": [8, 8, 16, 16, 16], "match_dim": 16, "context_widths": [8, 16, 16, 16],
        "hidden_dims": [16, 16, 16], "n_gru_layers": 1, "motion_dim": 16, "reg_widths": [8, 8, 8, 8],
        "max_disp": 64}


def _cfg(ds, out, steps):
    return TrainConfig(dataset=str(ds), out=str(out), steps=steps, batch=2, iters=2, size=(64, 64), ckpt_every=2,
                       val_every=2, val_samples=1, log_every=1, threads=2, stereo=TINY)


def test_sampler_shards_and_resumes():
    full = list(EpochSampler(10, seed=0))
    s = EpochSampler(10, seed=0)
    s.set_epoch(0, skip=4)
    assert list(s) == full[4:]
    r0, r1 = EpochSampler(10, 0, 0, 2), EpochSampler(10, 0, 1, 2)
    assert sorted(list(r0) + list(r1)) == sorted(full)


@pytest.mark.slow
def test_train_checkpoint_resume(synthetic_dataset, tmp_path):
    out = tmp_path / "run"
    summary = train_stereo(_cfg(synthetic_dataset, out, 2))
    assert summary["step"] == 2 and (out / "last.pt").is_file()
    log = [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]
    assert any("loss" in e for e in log) and any("val_epe" in e for e in log)
    cfg_doc = json.loads((out / "config.json").read_text())
    assert cfg_doc["stereo"]["variant"] == "full" and cfg_doc["train"]["steps"] == 2
    with pytest.raises(SpaceposeError, match="--resume"):
        train_stereo(_cfg(synthetic_dataset, out, 3))
    summary = train_stereo(_cfg(synthetic_dataset, out, 3), resume=True)
    ckpt = load_checkpoint(out / "last.pt")
    assert summary["step"] == 3 and ckpt["step"] == 3
    assert ckpt["scheduler"]["last_epoch"] == 3 and "rng" in ckpt


@pytest.mark.slow
def test_torchrun_two_processes(synthetic_dataset, tmp_path):
    """The same code under ``torchrun --nproc_per_node 2`` (gloo on CPU): DDP, sharded sampler, one checkpoint."""
    import subprocess
    import sys

    out = tmp_path / "ddp"
    driver = tmp_path / "driver.py"
    driver.write_text(
        "import json, sys\n"
        "from spacepose.tools.train_stereo import TrainConfig, train_stereo\n"
        f"cfg = TrainConfig(dataset={str(synthetic_dataset)!r}, out={str(out)!r}, steps=2, batch=1, iters=2,\n"
        "                  size=(64, 64), ckpt_every=2, val_every=100, log_every=1, threads=1,\n"
        f"                  stereo={TINY!r})\n"
        "train_stereo(cfg)\n")
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                           str(driver)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    doc = json.loads((out / "config.json").read_text())
    assert doc["world_size"] == 2
    assert load_checkpoint(out / "last.pt")["step"] == 2


@pytest.mark.slow
def test_init_fine_tunes_from_weights_with_fresh_schedule(synthetic_dataset, tmp_path):
    import dataclasses

    base = tmp_path / "base"
    train_stereo(_cfg(synthetic_dataset, base, 2))
    saved = load_checkpoint(base / "last.pt")
    ft = tmp_path / "ft"
    data = tmp_path / "data"     # a copy with a rendered set's manifest: its seed is what the checkpoint records
    shutil.copytree(synthetic_dataset, data)
    (data / "dataset.json").write_text(json.dumps({"seed": 42, "count": 10, "size": [64, 48]}))
    cfg = dataclasses.replace(_cfg(data, ft, 1), init=str(base / "last.pt"), val_every=100,
                              oversample={"mixed": 3})
    from spacepose.tools import train_stereo as ts

    loaded = {}
    real = ts.init_from

    def spy(model, path, config, device):
        real(model, path, config, device)
        loaded.update({k: v.clone() for k, v in model.state_dict().items()})

    ts.init_from = spy
    try:
        train_stereo(cfg)
    finally:
        ts.init_from = real
    for key, value in saved["model"].items():  # the weights it started from are the checkpoint's
        assert torch.equal(loaded[key], value), key
    ckpt = load_checkpoint(ft / "last.pt")
    assert ckpt["step"] == 1 and ckpt["scheduler"]["last_epoch"] == 1  # a new schedule, not the old one's
    doc = json.loads((ft / "config.json").read_text())
    samples = 6 + 2 * sum(r == "mixed" for r in _regimes(synthetic_dataset))
    assert doc["train_frames"] == samples
    assert ckpt["dataset"] == doc["dataset"] == {"path": str(data), "seed": 42, "size": 10, "image_size": [64, 48],
                                                 "train_frames": 6, "train_samples": samples,
                                                 "oversample": {"mixed": 3}}
    assert saved["dataset"]["seed"] is None and "train_samples" not in saved["dataset"]  # no manifest, no oversample
    other = dataclasses.replace(cfg, out=str(tmp_path / "bad"), stereo={**TINY, "reg_widths": [8, 8, 8, 16]})
    with pytest.raises(SpaceposeError, match="differs"):
        train_stereo(other)


def _regimes(ds):
    from spacepose.tools.stereo_data import read_labels

    return [r.regime for r in read_labels(ds, "train")]


def test_target_weight_reaches_the_loss(synthetic_dataset, tmp_path, monkeypatch):
    import dataclasses

    from spacepose.tools import train_stereo as ts

    seen = []
    real = ts._sequence_loss

    def spy(init_disp, preds, gt, valid, max_disp, weight=None):
        seen.append(weight)
        return real(init_disp, preds, gt, valid, max_disp, weight)

    monkeypatch.setattr(ts, "_sequence_loss", spy)
    cfg = dataclasses.replace(_cfg(synthetic_dataset, tmp_path / "tw", 1), target_weight=4.0, val_every=100)
    train_stereo(cfg)
    assert len(seen) == 1 and seen[0] is not None
    assert set(torch.unique(seen[0]).tolist()) <= {1.0, 4.0} and float(seen[0].max()) == 4.0
    seen.clear()
    train_stereo(dataclasses.replace(cfg, out=str(tmp_path / "ew"), edge_weight=3.0, edge_radius=2))
    assert len(seen) == 1 and float(seen[0].max()) == 12.0  # target pixels on the silhouette: 4 x 3
    assert set(torch.unique(seen[0]).tolist()) <= {1.0, 4.0, 12.0}


def test_time_limit_stops_with_a_resumable_checkpoint(synthetic_dataset, tmp_path):
    import dataclasses

    out = tmp_path / "tl"
    cfg = dataclasses.replace(_cfg(synthetic_dataset, out, 5), time_limit_s=0.0, val_every=100, ckpt_every=100)
    summary = train_stereo(cfg)
    assert summary["step"] == 1 and load_checkpoint(out / "last.pt")["step"] == 1
    summary = train_stereo(dataclasses.replace(cfg, time_limit_s=None), resume=True)
    assert summary["step"] == 5


def test_schedule_pacer_keeps_the_schedule_on_the_clock(monkeypatch):
    from spacepose.tools import training_common as tc

    clock = [100.0]
    monkeypatch.setattr(tc.time, "perf_counter", lambda: clock[0])
    model = torch.nn.Linear(2, 2)
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 1e-3, total_steps=1000 + 100, pct_start=0.01,
                                                cycle_momentum=False, anneal_strategy="linear")
    pacer = tc.SchedulePacer(1000, 10.0)
    assert pacer.step(sched) == 1                 # no time has passed: one step, as without a pacer
    clock[0] += 5.0                                # half the time: the schedule jumps to step 500
    assert pacer.step(sched) == 500
    lr_half = sched.get_last_lr()[0]
    clock[0] += 0.001                              # ahead of the clock: one step at a time again
    assert pacer.step(sched) == 501
    clock[0] += 100.0                              # past the limit: never beyond the run's steps
    assert pacer.step(sched) == 1000
    assert sched.get_last_lr()[0] < 0.2 * lr_half  # annealed to (near) its end
    with pytest.raises(SpaceposeError):
        tc.SchedulePacer(0, 10.0)
    with pytest.raises(SpaceposeError):
        tc.SchedulePacer(10, 0.0)


def test_pace_lr_anneals_a_run_stopped_by_its_time_limit(synthetic_dataset, tmp_path):
    import dataclasses

    base = dataclasses.replace(_cfg(synthetic_dataset, tmp_path / "plain", 10000), time_limit_s=3.0, val_every=10**6,
                               ckpt_every=10**6, lr=1e-3)
    train_stereo(base)
    paced = dataclasses.replace(base, out=str(tmp_path / "paced"), pace_lr=True)
    train_stereo(paced)

    def schedule_and_steps(out):
        ckpt = load_checkpoint(out / "last.pt")
        return ckpt["scheduler"]["last_epoch"], ckpt["step"]

    plain_at, plain_steps = schedule_and_steps(tmp_path / "plain")
    paced_at, paced_steps = schedule_and_steps(tmp_path / "paced")
    assert plain_steps < 10000 and paced_steps < 10000     # both stopped by the clock
    assert plain_at == plain_steps                           # without pacing the schedule is where the steps are
    assert paced_at >= 9000                                  # paced: it ran (nearly) to its end in the time


@pytest.mark.slow
def test_exported_graph_records_the_data_seed_not_the_training_seed(synthetic_dataset, tmp_path, monkeypatch):
    import dataclasses

    from spacepose.export.metadata import COMMIT_ENV
    from spacepose.export.onnx_stereo import export_checkpoint
    from spacepose.onnx_session import read_metadata

    data = tmp_path / "data"
    shutil.copytree(synthetic_dataset, data)
    (data / "dataset.json").write_text(json.dumps({"seed": 42, "count": 10, "size": [64, 48]}))
    monkeypatch.setenv(COMMIT_ENV, "c0ffee")       # what device_job --commit sets for its processes
    train_stereo(dataclasses.replace(_cfg(data, tmp_path / "run", 1), seed=7))
    ckpt_path = tmp_path / "run" / "last.pt"
    meta = export_checkpoint(ckpt_path, tmp_path / "a.onnx", iters=1, size=(64, 64), parity=False)["metadata"]
    assert meta["dataset"]["seed"] == 42 and meta["dataset"]["size"] == 10 and "training_seed" not in meta["dataset"]
    assert meta["training_commit"] == "c0ffee" == read_metadata(tmp_path / "a.onnx")["training_commit"]
    old = load_checkpoint(ckpt_path)    # a checkpoint from before the data seed was recorded
    del old["dataset"]["seed"]
    torch.save(old, tmp_path / "old.pt")
    meta = export_checkpoint(tmp_path / "old.pt", tmp_path / "b.onnx", iters=1, size=(64, 64), parity=False)["metadata"]
    assert "seed" not in meta["dataset"] and meta["dataset"]["training_seed"] == 7


def test_photometric_mode_reaches_the_samples_and_old_configs_load():
    cfg = TrainConfig(dataset="d", out="o", photometric="wide")
    assert cfg.crop_config().photometric == "wide" and cfg.crop_config().augment
    assert TrainConfig(dataset="d", out="o").crop_config().photometric == "mild"    # sessions 1-35's samples
    old = dataclasses.asdict(TrainConfig(dataset="d", out="o"))
    del old["photometric"]                                                          # a run's config.json before it
    assert TrainConfig(**old).photometric == "mild"
    with pytest.raises(ValueError, match="photometric"):
        TrainConfig(dataset="d", out="o", photometric="loud").crop_config()
