"""Session 40: are two row files of the same frames the same poses? (the shipped bundle re-run on another machine)

    python reports/rerun_s40/compare_rows.py NEW.json.gz OLD.json.gz [NEW2 OLD2 ...]

Prints, per pair: frames, valid in each, and the frames whose validity differs or whose valid pose's e_t or e_R
differ by more than 1e-5 m / 1e-4 deg (``shard_eval`` rows round to 6 digits). Session 40 ran
``python -m spacepose.tools.shard_eval data/tdrs640 --split test --workers 1 --out NEW`` (and data/tdrs1280_eval
--split train, data/tdrs640_restyle --split test) with the shipped bundle and compared with
reports/pose_{test640,unseen1280,restyle640}_s39/pose_eval.json.gz (output beside this file).
"""
from __future__ import annotations

import gzip
import json
import sys


def _frames(path: str) -> dict[str, dict]:
    return {r["frame"]: r for r in json.load(gzip.open(path, "rt"))["frames"]}


def main(paths: list[str]) -> int:
    if not paths or len(paths) % 2:
        raise SystemExit("give pairs NEW OLD")
    for new, old in zip(paths[::2], paths[1::2]):
        a, b = _frames(new), _frames(old)
        if a.keys() != b.keys():
            raise SystemExit(f"{new} and {old} are not of the same frames")
        differ = [f for f, r in a.items() if r["valid"] != b[f]["valid"] or (r["valid"] and (
            abs(r["e_t"] - b[f]["e_t"]) > 1e-5 or abs(r["e_R"] - b[f]["e_R"]) > 1e-4))]
        print(f"{new} vs {old}: {len(a)} frames, valid {sum(r['valid'] for r in a.values())} / "
              f"{sum(r['valid'] for r in b.values())}, frames that differ: {len(differ)} {differ[:10]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
