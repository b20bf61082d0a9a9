"""Tests of `spacepose profile` (runtime/cli_profile.py): table, JSON, exit code vs budget."""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # --import-mode=importlib: find the helpers
from _bundle_fixtures import make_bundle, synthetic_pair  # noqa: E402

from spacepose.calibration.rig import paper_rig, save_rig  # noqa: E402
from spacepose.cli import main  # noqa: E402
from spacepose.imageio import write_image  # noqa: E402


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    root = tmp_path_factory.mktemp("profile")
    bundle = make_bundle(root / "bundle")
    save_rig(paper_rig(640, 480), root / "rig.yaml")
    seq = root / "seq"
    for side in ("left", "right"):
        (seq / side).mkdir(parents=True)
    left, right = synthetic_pair()
    for i in range(3):
        write_image(seq / "left" / f"{i:06d}.png", left)
        write_image(seq / "right" / f"{i:06d}.png", right)
    return root, seq, bundle


def _run(root, seq, bundle, *extra):
    return main(["profile", str(seq), "--calib", str(root / "rig.yaml"), "--bundle", str(bundle), "--threads", "1",
                 *extra])


def test_within_generous_budget(setup, tmp_path, capsys):
    root, seq, bundle = setup
    budget = tmp_path / "budget.json"
    budget.write_text(json.dumps({"rate_hz": 0.01, "peak_rss_mb": 1e6, "cores": 1}))
    out = tmp_path / "profile.json"
    assert _run(root, seq, bundle, "--budget", str(budget), "--json", str(out)) == 0
    report = json.loads(out.read_text())
    assert report["frames"] == 2  # one warm-up frame
    assert {"stereo", "voting", "total"} <= set(report["stages_ms"])
    assert set(report["stages_ms"]["total"]) >= {"p50", "p95", "max"}
    assert report["peak_rss_mb"] > 0 and report["over_budget"] == []
    split = report["network_split"]
    assert 0.0 < split["network_ms_sum"] < split["total_ms_sum"] and 0.0 < split["non_network_share"] < 1.0
    text = capsys.readouterr().out
    assert "p95" in text and "peak RSS" in text


def test_over_budget_exits_1(setup, tmp_path, capsys):
    root, seq, bundle = setup
    budget = tmp_path / "budget.yaml"
    budget.write_text("rate_hz: 1000000\npeak_rss_mb: 1\n")
    assert _run(root, seq, bundle, "--budget", str(budget), "--warmup", "0") == 1
    assert "OVER BUDGET" in capsys.readouterr().out


def test_bad_budget_file(setup, tmp_path, capsys):
    root, seq, bundle = setup
    budget = tmp_path / "budget.json"
    budget.write_text('{"speed": 1}')
    assert _run(root, seq, bundle, "--budget", str(budget)) == 2
    assert "unknown keys" in capsys.readouterr().err


def test_refuses_to_overwrite_json(setup, tmp_path):
    root, seq, bundle = setup
    out = tmp_path / "profile.json"
    out.write_text("{}")
    assert _run(root, seq, bundle, "--json", str(out)) == 2
    assert out.read_text() == "{}"
