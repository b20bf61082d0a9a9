"""Tables and verdict of reports/sequence_s30/rule.txt (the stereo window in sequences, session 30).

    python reports/sequence_s30/judge.py [RUNS]

RUNS (default ``runs/s30``) holds ``sequence eval`` reports of the shipped bundle: ``seq_fNN.json`` /
``seq_cNN.json`` with the previous pose's window (the default until session 30) and ``nopw_seq_fNN.json`` /
``nopw_seq_cNN.json`` with ``--no-prior-window``; the sequences and commands are printed by
``python reports/sequence_s30/sequences.py fit|check`` (the ``nopw_`` runs add ``--no-prior-window`` and write to
``runs/s30/nopw_<name>.json``). When every run is there, the frames are cut to the columns used here and written to
``rows.json.gz`` beside this script; otherwise that committed file is read, so the verdict reproduces from the
repository alone. The fit sequences (seeds 3011-3034) were explored before the rule was written; the check
sequences (seeds 3051-3066) were rendered after it was committed.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
sys.path.insert(0, str(HERE))
from _rows import compact_rows  # noqa: E402
from sequences import sequences  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.confidence import calibrated_confidence  # noqa: E402
from spacepose.tools.calibrate_uncertainty import (confidence_check, coverage, normal_within,  # noqa: E402
                                                   pose_errors, within_tolerance)
from spacepose.tools.eval_pose import BAR_R_DEG, BAR_T_M  # noqa: E402

KEYS = ("frame", "valid", "tracked", "e_t", "e_R", "position_valid", "stereo_ms", "roi", "depth_tolerance_m",
        "position", "outline_chamfer_px", "e_pos", "e_pos_los")
MODES = {"prior window": "{}", "coarse window": "nopw_{}"}
WRONG_DEG, WRONG_M = 20.0, 0.5   # on e_t here (calibrate_uncertainty's wrong_poses uses the centre's miss)
FOCAL = 800.0   # 640x480 on the paper rig


def _rows(runs: Path) -> dict[str, list[dict]]:
    files = {mode.format(name): [runs / f"{mode.format(name)}.json"]
             for which in ("fit", "check") for name, *_ in sequences(which) for mode in MODES.values()}
    return compact_rows(files, HERE / "rows.json.gz", KEYS, defaults={"roi": None})


def summary(frames: list[dict], bundle) -> dict[str, float]:
    """The table's columns for ``frames``; the confidence from ``bundle``'s uncertainty and confidence sections."""
    v = [r for r in frames if r["valid"]]
    e_t, e_R = np.array([r["e_t"] for r in v]), np.array([r["e_R"] for r in v])
    sides = [r["roi"][2] - r["roi"][0] for r in v if r.get("roi")]
    err = pose_errors(v, FOCAL)
    p = normal_within(err, bundle.uncertainty, FOCAL, bundle.confidence)
    conf = np.array([calibrated_confidence(x, bundle.confidence) for x in p])
    check = confidence_check(conf, within_tolerance(err, bundle.confidence), err["e_t"], err["e_R"])
    return {"frames": len(frames), "valid": len(v), "tracked": sum(bool(r["tracked"]) for r in v),
            "wrong": int(np.sum((e_R > WRONG_DEG) | (e_t > WRONG_M))), "flips": int(np.sum(e_R > 90.0)),
            "within": int(np.sum((e_t <= BAR_T_M) & (e_R <= BAR_R_DEG))),
            "e_t_mean": float(e_t.mean()), "e_t_median": float(np.median(e_t)),
            "e_R_mean": float(e_R.mean()), "e_R_median": float(np.median(e_R)),
            "position_valid": sum(bool(r["position_valid"]) for r in frames),
            "stereo_ms_median": float(np.median([r["stereo_ms"] for r in frames if math.isfinite(r["stereo_ms"])])),
            "window_side_median": float(np.median(sides)) if sides else float("nan"),
            "confidence_mean": check["mean_confidence"], "share_within": check["share_within"],
            "spearman_t": check["spearman_t"]}


HEAD = (f"{'set':<8}{'mode':<15}{'frames':>7}{'valid':>6}{'tracked':>8}{'wrong':>6}{'>90':>4}{'within':>7}"
        f"{'e_t mean/med':>15}{'e_R mean/med':>14}{'pos':>5}{'stereo ms':>10}{'window':>7}{'conf/within':>12}"
        f"{'rho e_t':>8}")


def _line(which: str, mode: str, s: dict[str, float]) -> str:
    return (f"{which:<8}{mode:<15}{s['frames']:>7}{s['valid']:>6}{s['tracked']:>8}{s['wrong']:>6}{s['flips']:>4}"
            f"{s['within']:>7}{s['e_t_mean']:>8.3f}/{s['e_t_median']:.3f}{s['e_R_mean']:>8.2f}/{s['e_R_median']:.2f}"
            f"{s['position_valid']:>5}{s['stereo_ms_median']:>10.0f}{s['window_side_median']:>7.0f}"
            f"{s['confidence_mean']:>7.2f}/{s['share_within']:.2f}{s['spearman_t']:>8.2f}")


def by_frame_before(sequence_frames: list[list[dict]]) -> dict[str, list[dict]]:
    """The valid poses of the sequences, split by what came before: ``tracked`` (decided by the previous pose),
    ``after a valid frame`` (decided on their own, on the previous pose's window when the run used it) and
    ``after an invalid frame`` (decided on their own; the window from the coarse pass either way)."""
    groups: dict[str, list[dict]] = {"tracked": [], "after a valid frame": [], "after an invalid frame": []}
    for frames in sequence_frames:
        before = False
        for r in frames:
            if r["valid"]:
                key = "tracked" if r["tracked"] else "after a valid frame" if before else "after an invalid frame"
                groups[key].append(r)
            before = bool(r["valid"])
    return groups


def print_split(rows: dict[str, list[dict]], bundle) -> None:
    """What the rule's exploration saw: the fit sequences' valid poses with the previous pose's window, by the
    frame before (mean confidence against the share within the bar, and the per-axis normalised squared errors
    of the uncertainty model)."""
    print("fit sequences, the previous pose's window, valid poses by the frame before:")
    split = by_frame_before([rows[name] for name, *_ in sequences("fit")])
    for key, poses in split.items():
        err = pose_errors(poses, FOCAL)
        p = normal_within(err, bundle.uncertainty, FOCAL, bundle.confidence)
        conf = np.array([calibrated_confidence(x, bundle.confidence) for x in p])
        check = confidence_check(conf, within_tolerance(err, bundle.confidence), err["e_t"], err["e_R"])
        cov = coverage(err, bundle.uncertainty, FOCAL)
        print(f"  {key:<24}{check['poses']:>5} poses | confidence {check['mean_confidence']:.3f}, within "
              f"{check['share_within']:.3f} | NEES range {cov['nees_range']:.2f}, lateral {cov['nees_lateral']:.2f}, "
              f"rotation {cov['nees_rotation']:.2f}")


def main(argv: list[str]) -> int:
    rows = _rows(Path(argv[0]) if argv else Path("runs/s30"))
    bundle = load_bundle(None, verify_graphs=False)
    results = {}
    print(HEAD)
    for which in ("fit", "check"):
        names = [name for name, *_ in sequences(which)]
        for mode, pattern in MODES.items():
            frames = [r for name in names for r in rows[pattern.format(name)]]
            results[which, mode] = summary(frames, bundle)
            print(_line(which, mode, results[which, mode]))
    print("(wrong: e_R > 20 deg or e_t > 0.5 m; within: e_t <= 0.10 m and e_R <= 2 deg; pos: frames with a position; "
          "stereo ms: median per frame of the stereo stage, one thread; window: median side of a valid pose's stereo "
          "window, px (the fit sequences' prior-window runs did not record it); conf/within: mean confidence and "
          "share within of the valid poses)")
    print()
    print_split(rows, bundle)
    old, new = results["check", "prior window"], results["check", "coarse window"]
    fails = []
    fails += [f"1. wrong {new['wrong']} > {old['wrong']}"] if new["wrong"] > old["wrong"] else []
    fails += [f"2. > 90 deg {new['flips']} > {old['flips']}"] if new["flips"] > old["flips"] else []
    fails += [f"3. within {new['within']} < {old['within']}"] if new["within"] < old["within"] else []
    fails += [f"4. valid {new['valid']} < 0.85 x {old['valid']}"] if new["valid"] < 0.85 * old["valid"] else []
    fails += [f"5. e_t mean {new['e_t_mean']:.3f} > {old['e_t_mean']:.3f}"] if new["e_t_mean"] > old["e_t_mean"] else []
    print()
    print("verdict (rule.txt, the 16 check sequences, candidate = coarse window): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
