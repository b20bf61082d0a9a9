"""Session 39: frame-by-frame A/B of the runtime's own work. Two estimator processes, "old" (the runtime of another
commit) and "new" (this checkout), take turns on every frame, so that a machine whose speed drifts (this one's graphs
took 250-380 ms per 1,280x960 frame within minutes) slows both alike.

    git worktree add /tmp/s39/base 11c3a97 && mkdir -p /tmp/s39/oldpkg && ln -s /tmp/s39/base/runtime /tmp/s39/oldpkg/spacepose
    SP_BUNDLE=/tmp/s39/base/runtime/bundles/default python reports/profile_s39/ab_frames.py data/tdrs1280_eval 30 2 OUT.json

Both use the bundle ``SP_BUNDLE`` (session 38's, so that only the code differs). Prints and writes the mean time per
frame, in the graphs and outside them, and whether both reported the same poses.
"""
import json, os, subprocess, sys
from pathlib import Path
import numpy as np
folder, n, rounds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
py = sys.executable
child = str(Path(__file__).resolve().parent / "ab_child.py")
old = os.environ.get("SP_OLDPKG", "/tmp/s39/oldpkg")
envA = dict(os.environ, PYTHONPATH=old); envB = dict(os.environ); envB.pop("PYTHONPATH", None)
procs = {k: subprocess.Popen([py, child, folder], env=e, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
         for k, e in (("old", envA), ("new", envB))}
for p in procs.values(): assert p.stdout.readline().strip() == "ready"
res = {"old": [], "new": []}
order = ["old", "new"]
for r in range(rounds):
    for i in range(n):
        for k in (order if (i + r) % 2 == 0 else order[::-1]):
            procs[k].stdin.write(f"{i}\n"); procs[k].stdin.flush()
            res[k].append(json.loads(procs[k].stdout.readline()))
for p in procs.values(): p.stdin.close(); p.wait()
out = {}
for k, rows in res.items():
    rows = rows[n // 10:]  # drop a little warm-up
    tot = np.array([x["total"] for x in rows]); net = np.array([x["net"] for x in rows])
    out[k] = {"frames": len(rows), "total_ms_mean": tot.mean(), "network_ms_mean": net.mean(),
              "outside_ms_mean": (tot - net).mean(), "outside_share": 1 - net.sum() / tot.sum(),
              "outside_ms_p50": float(np.median(tot - net))}
    print(k, {a: round(float(b), 2) for a, b in out[k].items()})
same = all((a["valid"] == b["valid"]) and (a["t"] == b["t"]) for a, b in zip(res["old"], res["new"]))
print("the same poses:", same)
print(f"outside ms: old {out['old']['outside_ms_mean']:.1f}, new {out['new']['outside_ms_mean']:.1f} "
      f"(x{out['old']['outside_ms_mean'] / out['new']['outside_ms_mean']:.2f})")
json.dump({"folder": folder, "frames": n, "rounds": rounds, "bundle": os.environ.get("SP_BUNDLE"), **out, "same_poses": same},
          open(sys.argv[4], "w"), indent=1)
