"""bench_graphs' rounds: every backend's process runs once per round, in rotated order, calls pooled."""

from spacepose.tools.bench_graphs import add_round_speedups, run_rounds, summarize


def test_rounds_rotate_pool_and_keep_errors():
    jobs = [("stereo", "onnxruntime fp32", {"t": 10.0}), ("stereo", "torch eager fp32", {"t": 30.0}),
            ("pose", "onnxruntime fp32", {"t": 1.0}), ("pose", "broken", {"fail": True})]
    order = []

    def child(graph, kw):
        order.append((graph, kw.get("t")))
        if kw.get("fail"):
            return {"error": "no such graph"}
        base = kw["t"] * (1 + len(order) / 100)            # a drifting machine
        return summarize([base, base + 1, base + 2])

    rows = run_rounds(jobs, child, rounds=3)
    assert order[:3] == [("stereo", 10.0), ("stereo", 30.0), ("pose", 1.0)]
    assert order[4:6] == [("stereo", 30.0), ("stereo", 10.0)]              # round 2 starts at the next backend
    assert sum(1 for g, t in order if t is None) == 1                      # a failing backend is not re-run
    by = {(r["graph"], r["backend"]): r for r in rows}
    assert by[("stereo", "onnxruntime fp32")]["calls"] == 9 and len(by[("stereo", "onnxruntime fp32")]["round_medians_ms"]) == 3
    assert 10.0 < by[("stereo", "onnxruntime fp32")]["median_ms"] < 13.5
    assert by[("pose", "broken")] == {"graph": "pose", "backend": "broken", "error": "no such graph"}
    assert [r["backend"] for r in rows] == [j[1] for j in jobs]


def test_summarize():
    out = summarize([3.0, 1.0, 2.0, 10.0])
    assert out["calls"] == 4 and out["median_ms"] == 2.5 and out["times_ms"] == [3.0, 1.0, 2.0, 10.0]
    assert out["p95_ms"] > 8.0 and abs(out["mean_ms"] - 4.0) < 1e-12


def test_round_speedups_pair_each_round_with_torch():
    rows = [{"graph": "stereo", "backend": "onnxruntime fp32", "median_ms": 1.0, "round_medians_ms": [100.0, 50.0]},
            {"graph": "stereo", "backend": "torch eager fp32", "median_ms": 1.0, "round_medians_ms": [150.0, 100.0]},
            {"graph": "stereo", "backend": "broken", "error": "x"},
            {"graph": "pose", "backend": "onnxruntime fp32", "median_ms": 1.0, "round_medians_ms": [10.0]}]
    add_round_speedups(rows)
    assert rows[0]["round_speedups"] == [1.5, 2.0] and rows[1]["round_speedups"] == [1.0, 1.0]
    assert "round_speedups" not in rows[2] and "round_speedups" not in rows[3]   # no torch row for pose
