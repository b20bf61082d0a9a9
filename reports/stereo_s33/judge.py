"""Tables and verdict of reports/stereo_s33/rule.txt (session 19's GPU-trained stereo graph in the current bundle).

    python reports/stereo_s33/judge.py --explore [RUNS]   # the spent sets the rule's background quotes
    python reports/stereo_s33/judge.py [RUNS]             # the fresh check sets and the verdict

RUNS (default ``runs/s33``) holds the reports of the commands in rule.txt: ``eval-pose`` folders
``<set>_<mode>/pose_eval.json``, ``eval-stereo`` folders ``stereo_<mode>/stereo_eval.json`` and ``sequence eval``
reports ``<mode>_<name>.json``; ``mode`` is ``base`` (the shipped bundle) or ``gpu19`` (the candidate: the shipped
bundle with ``stereo.onnx`` replaced by ``reports/stereo_s19/stereo_gpu19.onnx`` and the two range-bias keys
refitted, as rule.txt says; in the ``--explore`` runs the keys were still the shipped ones). When every
run of a part is there, its frames are cut to the columns used here and written beside this script
(``rows_explore.json.gz``, ``rows.json.gz``; the stereo metrics to ``stereo.json``); otherwise those committed files
are read, so the tables and the verdict reproduce from the repository alone. ``--explore`` reads RUNS (default
``runs``) ``{test,unseen,val3,val4}_<mode>/pose_eval.json`` (rule.txt's background names their commands) and the
sequences' reports in ``RUNS/s33``, and also prints the range-bias fit that set the candidate's two keys.

Wrong: a valid pose off by more than 20 deg or 0.5 m; within the bar: e_t <= 0.10 m and e_R <= 2 deg; > 90: a
valid pose more than 90 deg off. Position-only frames: session 32's table (reports/position_s32/judge.py).
"""
from __future__ import annotations

import gzip
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


seqs = _load("sequences_s33", HERE / "sequences.py")                   # this folder's sequence lists
pos32 = _load("judge_s32", HERE.parent / "position_s32" / "judge.py")   # position_table, print_table

MODES = ("base", "gpu19")
LABELS = {"base": "shipped", "gpu19": "candidate"}
KEYS = ("frame", "valid", "status", "e_t", "e_R", "position_valid", "e_pos", "e_pos_los", "depth_tolerance_m",
        "outline_chamfer_px", "outline_margin_px", "flip_prob", "confidence", "polish_deg", "distance", "regime",
        "decided_by")
SEQ_KEYS = ("frame", "valid", "tracked", "e_t", "e_R", "position_valid", "e_pos", "e_pos_los", "depth_tolerance_m",
            "outline_chamfer_px", "confidence", "polish_deg", "decided_by")
# eval-pose folders per set: (folder stems, what the set is)
EXPLORE_SETS = {"test": (["test"], "test split, 300 frames (data/tdrs640)"),
                "unseen": (["unseen"], "unseen 1280x960, 90 frames (data/tdrs1280_eval)"),
                "val3": (["val3"], "tdrs640_val3 (seed 9), train frames 0-400"),
                "val4": (["val4"], "tdrs640_val4 (seed 10), train frames 0-400")}
CHECK_SETS = {"a": (["a0", "a1"], "tdrs640_s33a (seed 3301), train frames 0-600"),
              "b": (["b"], "tdrs1280_s33b (seed 3302), its 54 train frames")}
STEREO_KEYS = ("epe", "d1", "bad1", "bad3", "rmse")


def wrong(r: dict) -> bool:
    return r["e_R"] > 20.0 or r["e_t"] > 0.5


def within(r: dict) -> bool:
    return r["e_t"] <= 0.10 and r["e_R"] <= 2.0


def counts(rows: list[dict]) -> dict[str, float]:
    v = [r for r in rows if r["valid"]]
    e_t, e_R = np.array([r["e_t"] for r in v]), np.array([r["e_R"] for r in v])
    return {"frames": len(rows), "valid": len(v), "wrong": sum(map(wrong, v)), "flips": int(np.sum(e_R > 90.0)),
            "rotated": int(np.sum(e_R > 20.0)),
            "within": sum(map(within, v)), "e_t_mean": float(e_t.mean()) if v else float("nan"),
            "e_t_median": float(np.median(e_t)) if v else float("nan"),
            "e_R_mean": float(e_R.mean()) if v else float("nan"),
            "e_R_median": float(np.median(e_R)) if v else float("nan"),
            "positions": sum(bool(r["position_valid"]) for r in rows)}


HEAD = (f"{'set':<9}{'bundle':<11}{'frames':>7}{'valid':>6}{'wrong':>6}{'>90':>4}{'within':>7}{'e_t mean/med':>15}"
        f"{'e_R mean/med':>14}{'positions':>10}")


def line(name: str, mode: str, c: dict[str, float]) -> str:
    return (f"{name:<9}{LABELS[mode]:<11}{c['frames']:>7}{c['valid']:>6}{c['wrong']:>6}{c['flips']:>4}{c['within']:>7}"
            f"{c['e_t_mean']:>8.3f}/{c['e_t_median']:.3f}{c['e_R_mean']:>8.2f}/{c['e_R_median']:.2f}"
            f"{c['positions']:>10}")


def pose_rows(runs: Path, seq_runs: Path, sets: dict, seq_which: str, rows_path: Path) -> dict[str, list[dict]]:
    """Every set's rows per mode (``<set>_<mode>``, ``seq_<mode>_<name>``): cut from the runs and written to
    ``rows_path`` when they are all there, else read from it."""
    files = {f"{name}_{m}": [runs / f"{stem}_{m}" / "pose_eval.json" for stem in stems]
             for name, (stems, _) in sets.items() for m in MODES}
    files.update({f"seq_{m}_{n}": [seq_runs / f"{m}_{n}.json"] for n, *_ in seqs.sequences(seq_which) for m in MODES})
    if not all(f.is_file() for fs in files.values() for f in fs):
        with gzip.open(rows_path, "rt") as fh:
            return json.load(fh)
    rows = {}
    for group, fs in files.items():
        keys = SEQ_KEYS if group.startswith("seq_") else KEYS
        rows[group] = [{k: r[k] if k != "decided_by" else r.get(k) for k in keys}
                       for f in fs for r in json.loads(f.read_text())["frames"]]
    with open(rows_path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
        fh.write(json.dumps(rows).encode())
    return rows


def report(rows: dict[str, list[dict]], sets: dict, seq_which: str) -> dict[str, dict[str, dict]]:
    """Print the table (every set, then the sequences, then all pooled) and return the counts per set and mode."""
    names = [n for n, *_ in seqs.sequences(seq_which)]
    out: dict[str, dict[str, dict]] = {}
    print(HEAD)
    for name in list(sets) + ["seq", "pooled"]:
        for m in MODES:
            if name == "seq":
                sel = [r for n in names for r in rows[f"seq_{m}_{n}"]]
            elif name == "pooled":
                sel = [r for s in sets for r in rows[f"{s}_{m}"]] + [r for n in names for r in rows[f"seq_{m}_{n}"]]
            else:
                sel = rows[f"{name}_{m}"]
            out.setdefault(name, {})[m] = counts(sel)
            print(line(name, m, out[name][m]))
    for name, (_, what) in sets.items():
        print(f"  {name}: {what}")
    print(f"  seq: {len(names)} sequences of 40 frames ({', '.join(names[:1])} ... {names[-1]}; "
          f"reports/stereo_s33/sequences.py {seq_which})")
    print("(wrong: e_R > 20 deg or e_t > 0.5 m; within: e_t <= 0.10 m and e_R <= 2 deg; positions: frames with a "
          "valid position)")
    print()
    print("position-only frames (independent frames; session 32's columns):")
    for name in sets:
        for m in MODES:
            pos32.print_table(f"{name} {LABELS[m]}", pos32.position_table(rows[f"{name}_{m}"]))
    return out


def by_regime(rows: dict[str, list[dict]], sets: dict) -> None:
    print("per regime, independent frames pooled (valid / wrong / within):")
    for regime in ("sun", "albedo", "penumbra", "mixed"):
        cells = []
        for m in MODES:
            c = counts([r for s in sets for r in rows[f"{s}_{m}"] if r["regime"] == regime])
            cells.append(f"{LABELS[m]} {c['valid']:>4} / {c['wrong']} / {c['within']:>3}")
        print(f"  {regime:<9}" + "    ".join(cells))


def stereo_metrics(runs: Path) -> dict[str, dict[str, float]]:
    files = {m: runs / f"stereo_{m}" / "stereo_eval.json" for m in MODES}
    path = HERE / "stereo.json"
    if all(f.is_file() for f in files.values()):
        got = {}
        for m, f in files.items():
            ours = json.loads(f.read_text())["ours"]
            got[m] = {"frames": ours["overall"]["frames"], **{k: ours["overall"][k] for k in STEREO_KEYS}}
        path.write_text(json.dumps(got, indent=1) + "\n")
    return json.loads(path.read_text())


def verdict(c: dict[str, dict[str, dict]], stereo: dict[str, dict[str, float]], rows: dict[str, list[dict]]) -> str:
    """rule.txt's clauses S1 and P1-P6."""
    base, cand = c["pooled"]["base"], c["pooled"]["gpu19"]
    fails = [f"S1. EPE {stereo['gpu19']['epe']:.3f} >= {stereo['base']['epe']:.3f}"
             ] if not stereo["gpu19"]["epe"] < stereo["base"]["epe"] else []
    fails += [f"S1. D1 {stereo['gpu19']['d1']:.2f} >= {stereo['base']['d1']:.2f}"
              ] if not stereo["gpu19"]["d1"] < stereo["base"]["d1"] else []
    flips = {name: per["gpu19"]["flips"] for name, per in c.items() if name != "pooled" and per["gpu19"]["flips"]}
    fails += [f"P1. valid poses > 90 deg off: {flips}"] if flips else []
    share_base, share_cand = base["wrong"] / max(base["valid"], 1), cand["wrong"] / max(cand["valid"], 1)
    fails += ([f"P2. wrong share {100 * share_cand:.2f} % > {100 * share_base:.2f} % + 1.0"]
              if share_cand > share_base + 0.010 else [])
    fails += ([f"P3. > 20 deg {cand['rotated']} > {base['rotated']} + 1"]
              if cand["rotated"] > base["rotated"] + 1 else [])
    fails += ([f"P4. within {cand['within']} < 1.10 x {base['within']}"]
              if cand["within"] < 1.10 * base["within"] else [])
    fails += [f"P5. valid {cand['valid']} < {base['valid']}"] if cand["valid"] < base["valid"] else []
    t_base, t_cand = pos32.position_table(rows["a_base"])["all"], pos32.position_table(rows["a_gpu19"])["all"]
    fails += ([f"P6. set a position-only e_pos {t_cand['e_pos']:.3f} > {t_base['e_pos']:.3f} + 0.02"]
              if t_cand["e_pos"] > t_base["e_pos"] + 0.02 else [])
    fails += ([f"P6. set a position-only within tau {t_cand['within_tau']:.3f} < {t_base['within_tau']:.3f} - 0.02"]
              if t_cand["within_tau"] < t_base["within_tau"] - 0.02 else [])
    return "verdict (rule.txt): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails))


def fit_range_keys(rows: dict[str, list[dict]], sets: dict) -> None:
    """The range-bias keys (share k of the depth tolerance) that minimise the mean |range error| of each source of
    position-only frames, per mode, on a grid; the runs had the shipped keys, which are undone first."""
    shipped = {"outline": 0.07, "registered": 0.24}
    print("range-bias keys refitted on these rows (k * tau, least mean |range error|, grid step 0.005):")
    for m in MODES:
        for name in ("outline", "registered"):
            sel = [r for s in sets for r in rows[f"{s}_{m}"] if pos32.source(r) == name]
            tau = np.array([r["depth_tolerance_m"] for r in sel])
            los = np.array([r["e_pos_los"] for r in sel]) + shipped[name] * tau
            ks = np.linspace(-0.2, 0.5, 141)
            cost = [float(np.abs(los - k * tau).mean()) for k in ks]
            i = int(np.argmin(cost))
            print(f"  {LABELS[m]:<10}{name:<11}{len(sel):>4} frames  k = {ks[i]:+.3f}: "
                  f"mean |range error| {cost[i]:.4f} m "
                  f"(shipped k {shipped[name]}: {float(np.abs(los - shipped[name] * tau).mean()):.4f} m)")


def print_stereo(stereo: dict[str, dict[str, float]], what: str) -> None:
    print(f"stereo over target pixels, {what}:")
    for m in MODES:
        s = stereo[m]
        print(f"  {LABELS[m]:<10} {s['frames']} frames  EPE {s['epe']:.3f} px  D1 {s['d1']:.2f} %  "
              f"bad-1 {s['bad1']:.2f} %"
              f"  bad-3 {s['bad3']:.2f} %  RMSE {s['rmse']:.3f} px")


def main(argv: list[str]) -> int:
    explore = argv[:1] == ["--explore"]
    argv = argv[1:] if explore else argv
    runs = Path(argv[0]) if argv else Path("runs/s33" if not explore else "runs")
    if explore:
        rows = pose_rows(runs, runs / "s33", EXPLORE_SETS, "explore", HERE / "rows_explore.json.gz")
        print("exploration on spent sets (before rule.txt was written):")
        rot = report(rows, EXPLORE_SETS, "explore")["pooled"]
        print(f"pooled valid poses > 20 deg off in rotation: shipped {rot['base']['rotated']}, "
              f"candidate {rot['gpu19']['rotated']}")
        print()
        by_regime(rows, EXPLORE_SETS)
        print()
        fit_range_keys(rows, EXPLORE_SETS)
        return 0
    rows = pose_rows(runs, runs, CHECK_SETS, "check", HERE / "rows.json.gz")
    stereo = stereo_metrics(runs)
    c = report(rows, CHECK_SETS, "check")
    print()
    by_regime(rows, CHECK_SETS)
    print()
    print_stereo(stereo, "the 100 test-split frames of tdrs640_s33a")
    print()
    base, cand = c["pooled"]["base"], c["pooled"]["gpu19"]
    share = {m: 100 * c["pooled"][m]["wrong"] / max(c["pooled"][m]["valid"], 1) for m in MODES}
    print(f"pooled: valid poses > 20 deg off in rotation: shipped {base['rotated']}, candidate {cand['rotated']}; "
          f"wrong share {share['base']:.2f} % against {share['gpu19']:.2f} %")
    print(verdict(c, stereo, rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
