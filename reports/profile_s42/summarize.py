"""Session 42: the default bundle with and without the range fit at 1,280x960, 2 threads, runs interleaved.

    spacepose profile data/tdrs1280_eval --calib data/tdrs1280_eval/rig.yaml --limit 30 [--bundle NORANGE]
        --json reports/profile_s42/profile1280_{new,old}_{1,2}.json --force
    python reports/profile_s42/summarize.py

NORANGE is a copy of the default bundle without its ``range_fit`` section (session 41's bundle). The machine's speed
drifts by tens of percent within minutes (session 39), so the totals are noisy; the fit's own stage time
(``range_fit``, on the frames with a valid pose) is the figure to read.
"""
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
print("| run | bundle | total p50 / p95 ms | range_fit p50 / max ms (frames) | outside the graphs | peak RSS MiB |")
print("|---|---|---|---|---|---|")
for r in ("new_1", "old_1", "new_2", "old_2"):
    d = json.loads((HERE / f"profile1280_{r}.json").read_text())
    st, rf = d["stages_ms"], d["stages_ms"].get("range_fit")
    fit = "-" if rf is None else f"{rf['p50']:.1f} / {rf['max']:.1f} ({rf['n']})"
    print(f"| {r} | {'with the range fit' if r.startswith('new') else 'without (session 41)'} | "
          f"{st['total']['p50']:.0f} / {st['total']['p95']:.0f} | {fit} | "
          f"{100 * d['network_split']['non_network_share']:.1f} % | {d['peak_rss_mb']:.0f} |")
