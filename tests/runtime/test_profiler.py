"""Tests of spacepose.profiler (never asserts a timing value)."""

import json

import pytest

from spacepose.profiler import (DEFAULT_BUDGET, Budget, StageTimer, check_budget, current_rss_bytes, load_budget,
                                peak_rss_bytes, summarize_timings)


class TestStageTimer:
    def test_records_and_accumulates(self):
        timer = StageTimer()
        with timer.stage("a"):
            pass
        with timer.stage("b"):
            pass
        with timer.stage("a"):
            pass
        assert list(timer.timings_ms) == ["a", "b"]
        assert all(v >= 0.0 for v in timer.timings_ms.values())
        assert timer.total_ms == pytest.approx(sum(timer.timings_ms.values()))

    def test_records_when_body_raises(self):
        timer = StageTimer()
        with pytest.raises(RuntimeError):
            with timer.stage("boom"):
                raise RuntimeError("x")
        assert "boom" in timer.timings_ms


def test_rss_is_positive_and_peak_not_below_current():
    assert peak_rss_bytes() > 0
    assert peak_rss_bytes() >= current_rss_bytes() > 0


class TestBudget:
    def test_default(self):
        assert DEFAULT_BUDGET == Budget(rate_hz=1.0, peak_rss_mb=1536.0, cores=2)
        assert DEFAULT_BUDGET.frame_ms == 1000.0
        assert load_budget(None) == DEFAULT_BUDGET

    def test_json_and_yaml(self, tmp_path):
        (tmp_path / "b.json").write_text(json.dumps({"rate_hz": 2, "peak_rss_mb": 800, "cores": 4}))
        assert load_budget(tmp_path / "b.json") == Budget(2, 800, 4)
        (tmp_path / "b.yaml").write_text("%YAML:1.0\n# flight computer\nrate_hz: 0.5\npeak_rss_mb: 1024  # MiB\n")
        assert load_budget(tmp_path / "b.yaml") == Budget(rate_hz=0.5, peak_rss_mb=1024)

    @pytest.mark.parametrize("text, match", [
        ('{"rate": 1}', "unknown keys"), ('{"rate_hz": -1}', "positive"), ('{"cores": 0}', "cores"), ("[", "JSON"),
    ])
    def test_bad_files(self, tmp_path, text, match):
        (tmp_path / "b.json").write_text(text)
        with pytest.raises(ValueError, match=match):
            load_budget(tmp_path / "b.json")

    def test_bad_yaml_value(self, tmp_path):
        (tmp_path / "b.yaml").write_text("rate_hz: fast\n")
        with pytest.raises(ValueError, match="rate_hz"):
            load_budget(tmp_path / "b.yaml")


def test_summarize_and_check_budget():
    samples = [{"stereo": 100.0, "pose": 50.0}, {"stereo": 300.0}, {"stereo": 200.0, "pose": 70.0}]
    summary = summarize_timings(samples)
    assert summary["stereo"]["p50"] == 200.0 and summary["stereo"]["max"] == 300.0 and summary["stereo"]["n"] == 3
    assert summary["pose"]["n"] == 2
    assert summary["total"]["max"] == 300.0
    assert check_budget(summary, 10 * 2**20, Budget(rate_hz=1.0, peak_rss_mb=100)) == []
    problems = check_budget(summary, 200 * 2**20, Budget(rate_hz=10.0, peak_rss_mb=100))
    assert len(problems) == 2 and "p95" in problems[0] and "RSS" in problems[1]


def test_network_split():
    from spacepose.profiler import network_split

    out = network_split([100.0, 200.0, 0.0], [90.0, 150.0, 0.0])
    assert out["network_ms_sum"] == 240.0 and out["total_ms_sum"] == 300.0
    assert out["non_network_share"] == pytest.approx(60.0 / 300.0)
    assert out["non_network_share_p50"] == pytest.approx(0.1)  # median of 0.1, 0.25, 0.0
    with pytest.raises(ValueError):
        network_split([1.0], [])
    with pytest.raises(ValueError):
        network_split([], [])


def test_stage_timer_network_accumulates():
    from spacepose.profiler import StageTimer

    timer = StageTimer()
    timer.add_network(2.5)
    timer.add_network(1.5)
    assert timer.network_ms == 4.0 and timer.timings_ms == {}
