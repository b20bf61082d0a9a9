"""Session 41: the default bundle with and without the outline refiner at 1,280x960, 2 threads, runs interleaved.

    spacepose profile data/tdrs1280_eval --calib data/tdrs1280_eval/rig.yaml --limit 30 [--bundle NOREF]
        --json reports/profile_s41/profile1280_{new,old}_{1,2}.json --force
    python reports/profile_s41/summarize.py

NOREF is a copy of the default bundle without its ``outline_refiner`` section and ``outline.onnx`` (session 39's
bundle). The machine's speed drifts by tens of percent within minutes (session 39), so the totals are noisy; the
refiner's own graph time (``outline_net``) and the peak RSS are the figures to read.
"""
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
print("| run | bundle | total p50 / p95 ms | silhouette p50 ms | outline_net p50 ms (frames) | outside the graphs "
      "| peak RSS MiB |")
print("|---|---|---|---|---|---|---|")
for r in ("new_1", "old_1", "new_2", "old_2"):
    d = json.loads((HERE / f"profile1280_{r}.json").read_text())
    st, on = d["stages_ms"], d["stages_ms"].get("outline_net")
    print(f"| {r} | {'with the refiner' if r.startswith('new') else 'without (session 39)'} | "
          f"{st['total']['p50']:.0f} / {st['total']['p95']:.0f} | {st['silhouette']['p50']:.1f} | "
          f"{'-' if on is None else format(on['p50'], '.1f') + ' (' + str(on['n']) + ')'} | "
          f"{100 * d['network_split']['non_network_share']:.1f} % | {d['peak_rss_mb']:.0f} |")
