"""One side of reports/profile_s39/ab_frames.py: estimates the frame whose index it reads on stdin, prints its timings."""
import json, os, sys
from pathlib import Path
from spacepose.cli_estimate import list_frames, read_pair
from spacepose.estimator import PoseEstimator
folder = Path(sys.argv[1])
est = PoseEstimator(folder / "rig.yaml", bundle=os.environ.get("SP_BUNDLE") or None, threads=2)
names = list_frames(folder)
pairs = {}
print("ready", flush=True)
for line in sys.stdin:
    i = int(line)
    if i not in pairs:
        pairs = {i: read_pair(folder, names[i])}
    res = est.estimate(*pairs[i])
    print(json.dumps({"total": sum(res.timings_ms.values()), "net": res.network_ms, "stages": res.timings_ms,
                      "valid": bool(res.valid), "t": list(map(float, res.t)) if res.valid else None}), flush=True)
