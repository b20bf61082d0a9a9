"""Benchmark spacepose.voting.mean_shift against sklearn.cluster.MeanShift.

Synthetic FFB6D-like centre votes: a fraction of the points vote tightly (sigma = bandwidth / 3)
around the object centre ~10 m away, a smaller blob votes elsewhere, the rest are uniform outliers.
For each point count it times our seeded non-blurring mean shift (flat and Gaussian kernels) and
scikit-learn's MeanShift (flat kernel, bin_seeding=False, every point a seed), and reports the
distance between the top modes.

    .venv/bin/python tools/bench_voting.py --out bench_voting.json
    .venv/bin/python -m spacepose.tools.bench_voting --sizes 2000 --repeats 20

Prints a table and writes JSON to --out. Not a test: it asserts nothing about timings.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from spacepose.voting import mean_shift

BANDWIDTH = 0.05


def make_votes(n: int, seed: int = 0) -> np.ndarray:
    """(n, 3) centre votes: 65 % object, 15 % second blob, 20 % uniform outliers in a 2 m box."""
    rng = np.random.default_rng(seed)
    centre = np.array([0.3, -0.2, 10.0])
    n_obj, n_blob = int(0.65 * n), int(0.15 * n)
    return np.concatenate([
        rng.normal(centre, BANDWIDTH / 3, (n_obj, 3)),
        rng.normal(centre + [0.4, 0.1, 0.0], BANDWIDTH / 3, (n_blob, 3)),
        centre + rng.uniform(-1.0, 1.0, (n - n_obj - n_blob, 3)),
    ])


def time_call(fn, repeats: int, warm_up: bool = True) -> tuple[float, object]:
    """Median wall time (s) of ``repeats`` calls (after one untimed call if ``warm_up``), last result."""
    result = fn() if warm_up else None
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def bench_size(n: int, repeats: int, n_seeds: int, sklearn_repeats: int, run_sklearn: bool) -> dict:
    votes = make_votes(n)
    row: dict = {"n_points": n, "bandwidth": BANDWIDTH, "n_seeds": n_seeds}
    for kernel in ("flat", "gaussian"):
        sec, res = time_call(lambda k=kernel: mean_shift(votes, BANDWIDTH, kernel=k, n_seeds=n_seeds),
                             repeats)
        row[f"ours_{kernel}_ms"] = sec * 1e3
        row[f"ours_{kernel}_iters"] = res.n_iter
        row[f"ours_{kernel}_top_mode"] = res.modes[0].tolist()
        row[f"ours_{kernel}_top_support"] = int(res.support[0])
    if run_sklearn:
        from sklearn.cluster import MeanShift

        sec, est = time_call(lambda: MeanShift(bandwidth=BANDWIDTH, bin_seeding=False).fit(votes),
                             max(1, sklearn_repeats), warm_up=False)
        row["sklearn_ms"] = sec * 1e3
        row["sklearn_top_mode"] = est.cluster_centers_[0].tolist()
        row["speedup_flat"] = row["sklearn_ms"] / row["ours_flat_ms"]
        row["speedup_gaussian"] = row["sklearn_ms"] / row["ours_gaussian_ms"]
        row["top_mode_diff_flat_m"] = float(np.linalg.norm(
            np.subtract(row["ours_flat_top_mode"], row["sklearn_top_mode"])))
        row["top_mode_diff_gaussian_m"] = float(np.linalg.norm(
            np.subtract(row["ours_gaussian_top_mode"], row["sklearn_top_mode"])))
    return row


def print_table(rows: list[dict]) -> None:
    head = (f"{'points':>7} {'ours flat ms':>13} {'ours gauss ms':>14} {'sklearn ms':>11} "
            f"{'speedup flat':>13} {'speedup gauss':>14} {'|Δmode| flat m':>15} {'|Δmode| gauss m':>16}")
    print(head)
    print("-" * len(head))
    for r in rows:
        sk = r.get("sklearn_ms")
        print(f"{r['n_points']:>7} {r['ours_flat_ms']:>13.2f} {r['ours_gaussian_ms']:>14.2f} "
              + (f"{sk:>11.0f} {r['speedup_flat']:>12.0f}x {r['speedup_gaussian']:>13.0f}x "
                 f"{r['top_mode_diff_flat_m']:>15.2e} {r['top_mode_diff_gaussian_m']:>16.2e}"
                 if sk is not None else f"{'-':>11} {'-':>13} {'-':>14} {'-':>15} {'-':>16}"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[2000, 12800])
    parser.add_argument("--repeats", type=int, default=10, help="timed calls of ours (median)")
    parser.add_argument("--sklearn-repeats", type=int, default=1, help="timed sklearn fits (median)")
    parser.add_argument("--n-seeds", type=int, default=32)
    parser.add_argument("--no-sklearn", action="store_true", help="time ours only")
    parser.add_argument("--out", type=Path, default=Path("bench_voting.json"))
    args = parser.parse_args(argv)

    rows = [bench_size(n, args.repeats, args.n_seeds, args.sklearn_repeats, not args.no_sklearn)
            for n in args.sizes]
    print_table(rows)
    report = {
        "benchmark": "mean_shift vs sklearn.cluster.MeanShift (flat, bin_seeding=False)",
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "python": platform.python_version(), "numpy": np.__version__},
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
