"""Tables and verdict of reports/floor_s34/rule.txt (session 19's stereo graph with a floor of 0.08 on the
reported confidence, against the shipped bundle).

    python reports/floor_s34/judge.py [RUNS]             # round 1: rule.txt
    python reports/floor_s34/judge.py --round2 [RUNS]    # round 2: rule2.txt, both rounds pooled

RUNS (default ``runs/s34``) holds the reports of the commands in rule.txt: ``eval-pose`` folders
``<set>_<mode>/pose_eval.json``, ``eval-stereo`` folders ``stereo_<mode>/stereo_eval.json`` and ``sequence eval``
reports ``<mode>_<name>.json``; ``mode`` is ``base`` (the shipped bundle) or ``cand`` (rule.txt's candidate). When
every run is there, its frames are cut to the columns used here and written beside this script (``rows.json.gz``;
the stereo metrics to ``stereo.json``); otherwise those committed files are read, so the tables and the verdict
reproduce from the repository alone. Round 2 adds ``rows2.json.gz``: the runs of rule2.txt (sets ``c*``, ``d``, the
``check2`` sequences for ``base`` and ``cand``; the sequences of both rounds for ``floor``, the shipped bundle with the
floor alone, whose independent frames are the base rows with poses under the floor turned invalid).

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


seqs = _load("sequences_s34", HERE / "sequences.py")
s33 = _load("judge_s33", HERE.parent / "stereo_s33" / "judge.py")       # counts, wrong, within, KEYS
pos32 = s33.pos32                                                        # position_table, print_table

MODES = ("base", "cand")
LABELS = {"base": "shipped", "cand": "candidate"}
FLOOR = 0.08
SETS = {"a": (["a0", "a1", "a2"], "tdrs640_s34a (seed 3401), train frames 0-900"),
        "b": (["b"], "tdrs1280_s34b (seed 3402), its 54 train frames")}
SEQ_KEYS = s33.SEQ_KEYS + ("status", "detail")


SETS2 = {"a2": (["c0", "c1", "c2"], "tdrs640_s34c (seed 3441), train frames 0-900"),
         "b2": (["d"], "tdrs1280_s34d (seed 3442), its 54 train frames")}


def round2_files(runs: Path) -> dict[str, list[Path]]:
    """rule2.txt's runs per group."""
    files = {f"{name}_{m}": [runs / f"{stem}_{m}" / "pose_eval.json" for stem in stems]
             for name, (stems, _) in SETS2.items() for m in MODES}
    files.update({f"seq_{m}_{n}": [runs / f"{m}_{n}.json"] for n, *_ in seqs.sequences("check2")
                  for m in MODES + ("floor",)})
    files.update({f"seq_floor_{n}": [runs / f"floor_{n}.json"] for n, *_ in seqs.sequences("check")})
    return files


def pose_rows(runs: Path, rows_path: Path, files: dict[str, list[Path]] | None = None) -> dict[str, list[dict]]:
    """Every set's rows per mode (``<set>_<mode>``, ``seq_<mode>_<name>``): cut from the runs and written to
    ``rows_path`` when they are all there, else read from it. ``files``: the runs per group (round 1's by default)."""
    if files is None:
        files = {f"{name}_{m}": [runs / f"{stem}_{m}" / "pose_eval.json" for stem in stems]
                 for name, (stems, _) in SETS.items() for m in MODES}
        files.update({f"seq_{m}_{n}": [runs / f"{m}_{n}.json"] for n, *_ in seqs.sequences("check") for m in MODES})
    if not all(f.is_file() for fs in files.values() for f in fs):
        with gzip.open(rows_path, "rt") as fh:
            return json.load(fh)
    rows = {}
    for group, fs in files.items():
        keys = SEQ_KEYS if group.startswith("seq_") else s33.KEYS
        rows[group] = [{k: r.get(k) for k in keys} for f in fs for r in json.loads(f.read_text())["frames"]]
    with open(rows_path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
        fh.write(json.dumps(rows).encode())
    return rows


def floored(rows: list[dict], floor: float) -> list[dict]:
    """``rows`` with every valid pose under ``floor`` turned invalid (no position: a simulation for information)."""
    return [dict(r, valid=False) if r["valid"] and r["confidence"] < floor else r for r in rows]


def groups(rows: dict[str, list[dict]], name: str, mode: str) -> list[dict]:
    names = [n for n, *_ in seqs.sequences("check")]
    seq = [r for n in names for r in rows[f"seq_{mode}_{n}"]]
    if name == "seq":
        return seq
    if name == "pooled":
        return [r for s in SETS for r in rows[f"{s}_{mode}"]] + seq
    return rows[f"{name}_{mode}"]


HEAD = (f"{'set':<9}{'bundle':<22}{'frames':>7}{'valid':>6}{'wrong':>6}{'>20':>4}{'>90':>4}{'within':>7}"
        f"{'e_t mean/med':>15}{'e_R mean/med':>14}{'positions':>10}")


def line(name: str, label: str, c: dict[str, float]) -> str:
    return (f"{name:<9}{label:<22}{c['frames']:>7}{c['valid']:>6}{c['wrong']:>6}{c['rotated']:>4}{c['flips']:>4}"
            f"{c['within']:>7}{c['e_t_mean']:>8.3f}/{c['e_t_median']:.3f}{c['e_R_mean']:>8.2f}/"
            f"{c['e_R_median']:.2f}{c['positions']:>10}")


def report(rows: dict[str, list[dict]]) -> dict[str, dict[str, dict]]:
    """The table (every set, the sequences, all pooled); the counts per set and mode."""
    out: dict[str, dict[str, dict]] = {}
    print(HEAD)
    for name in list(SETS) + ["seq", "pooled"]:
        for m in MODES:
            out.setdefault(name, {})[m] = s33.counts(groups(rows, name, m))
            print(line(name, LABELS[m], out[name][m]))
        if name in SETS:
            print(line(name, f"shipped, floor {FLOOR} (sim)", s33.counts(floored(rows[f"{name}_base"], FLOOR))))
    for name, (_, what) in SETS.items():
        print(f"  {name}: {what}")
    names = [n for n, *_ in seqs.sequences("check")]
    print(f"  seq: {len(names)} sequences of 40 frames ({names[0]} ... {names[-1]}; "
          "reports/floor_s34/sequences.py check)")
    print("(wrong: e_R > 20 deg or e_t > 0.5 m; within: e_t <= 0.10 m and e_R <= 2 deg; positions: frames with a "
          "valid position; 'sim': the shipped bundle's rows with poses under the floor turned invalid, independent "
          "frames only, for information)")
    return out


def print_wrong(label: str, width: int, keyed: list[tuple[str, dict]]) -> None:
    """One line per wrong valid pose of ``keyed`` (where, row), labelled ``label`` padded to ``width``."""
    for where, r in keyed:
        if r["valid"] and s33.wrong(r):
            print(f"  {label:<{width}}{where:<8}{r['frame']}  e_R {r['e_R']:6.1f}  e_t {r['e_t']:.2f}  "
                  f"{r.get('decided_by') or '-':<12}chamfer {r['outline_chamfer_px']:.2f}  "
                  f"confidence {r['confidence']:.3f}")


def details(rows: dict[str, list[dict]]) -> None:
    """The wrong poses of both bundles, the candidate's confidence against its hit rate, the floor's refusals in
    sequences, per regime."""
    print("wrong valid poses (set, frame, e_R, e_t, route, chamfer, confidence):")
    for m in MODES:
        for name in list(SETS) + ["seq"]:
            print_wrong(LABELS[m], 10, [(name, r) for r in rows[f"{name}_{m}"]] if name in SETS else
                        [(n, r) for n, *_ in seqs.sequences("check") for r in rows[f"seq_{m}_{n}"]])
    print()
    print("confidence of valid poses against the share within the bar (pooled):")
    for m in MODES:
        v = [r for r in groups(rows, "pooled", m) if r["valid"]]
        c = np.array([r["confidence"] for r in v])
        w = np.array([s33.within(r) for r in v])
        print(f"  {LABELS[m]:<10} {len(v)} poses: mean confidence {c.mean():.3f}, within {w.mean():.3f}")
        for lo, hi in ((0.0, 0.1), (0.1, 0.2), (0.2, 0.4), (0.4, 1.01)):
            sel = (c >= lo) & (c < hi)
            if sel.any():
                print(f"    [{lo:.1f}, {min(hi, 1.0):.1f}): {int(sel.sum()):>4} poses, mean {c[sel].mean():.3f}, "
                      f"within {w[sel].mean():.3f}")
    print()
    for m in MODES:
        seq = groups(rows, "seq", m)
        refused = sum("min_valid" in (r.get("detail") or "") for r in seq)
        print(f"sequences, {LABELS[m]}: {refused} poses refused by the floor; tracked valid "
              f"{sum(bool(r['valid'] and r['tracked']) for r in seq)}")
    print()
    print("per regime, independent frames pooled (valid / wrong / within):")
    for regime in ("sun", "albedo", "penumbra", "mixed"):
        cells = []
        for m in MODES:
            c = s33.counts([r for s in SETS for r in rows[f"{s}_{m}"] if r["regime"] == regime])
            cells.append(f"{LABELS[m]} {c['valid']:>4} / {c['wrong']} / {c['within']:>3}")
        print(f"  {regime:<9}" + "    ".join(cells))
    print()
    print("position-only frames (independent frames; session 32's columns):")
    for m in MODES:
        pos32.print_table(f"a+b {LABELS[m]}", pos32.position_table(rows["a_" + m] + rows["b_" + m]))


def stereo_metrics(runs: Path) -> dict[str, dict[str, float]]:
    files = {m: runs / f"stereo_{m}" / "stereo_eval.json" for m in MODES}
    path = HERE / "stereo.json"
    if all(f.is_file() for f in files.values()):
        got = {}
        for m, f in files.items():
            ours = json.loads(f.read_text())["ours"]
            got[m] = {"frames": ours["overall"]["frames"], **{k: ours["overall"][k] for k in s33.STEREO_KEYS}}
        path.write_text(json.dumps(got, indent=1) + "\n")
    return json.loads(path.read_text())


def verdict(c: dict[str, dict[str, dict]], stereo: dict[str, dict[str, float]], rows: dict[str, list[dict]]) -> str:
    """rule.txt's clauses S1 and P1-P6."""
    base, cand = c["pooled"]["base"], c["pooled"]["cand"]
    fails = [f"S1. EPE {stereo['cand']['epe']:.3f} >= {stereo['base']['epe']:.3f}"
             ] if not stereo["cand"]["epe"] < stereo["base"]["epe"] else []
    fails += [f"S1. D1 {stereo['cand']['d1']:.2f} >= {stereo['base']['d1']:.2f}"
              ] if not stereo["cand"]["d1"] < stereo["base"]["d1"] else []
    flips = {name: per["cand"]["flips"] for name, per in c.items() if name != "pooled" and per["cand"]["flips"]}
    fails += [f"P1. valid poses > 90 deg off: {flips}"] if flips else []
    fails += [f"P2. wrong {cand['wrong']} > {base['wrong']}"] if cand["wrong"] > base["wrong"] else []
    fails += [f"P3. > 20 deg {cand['rotated']} > {base['rotated']}"] if cand["rotated"] > base["rotated"] else []
    fails += ([f"P4. within {cand['within']} < 1.10 x {base['within']}"]
              if cand["within"] < 1.10 * base["within"] else [])
    fails += ([f"P5. valid {cand['valid']} < 0.90 x {base['valid']}"]
              if cand["valid"] < 0.90 * base["valid"] else [])
    t_base = pos32.position_table(rows["a_base"] + rows["b_base"])["all"]
    t_cand = pos32.position_table(rows["a_cand"] + rows["b_cand"])["all"]
    fails += ([f"P6. position-only e_pos {t_cand['e_pos']:.3f} > {t_base['e_pos']:.3f} + 0.02"]
              if t_cand["e_pos"] > t_base["e_pos"] + 0.02 else [])
    fails += ([f"P6. position-only within tau {t_cand['within_tau']:.3f} < {t_base['within_tau']:.3f} - 0.03"]
              if t_cand["within_tau"] < t_base["within_tau"] - 0.03 else [])
    return "verdict (rule.txt): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails))


def round2(runs: Path) -> int:
    """rule2.txt: round 2's table, both rounds pooled, and the verdicts for B (cand) and A (floor)."""
    rows = {**pose_rows(runs, HERE / "rows.json.gz"), **pose_rows(runs, HERE / "rows2.json.gz", round2_files(runs))}
    for name in list(SETS) + list(SETS2):       # the floor's independent frames: the base rows, floored
        rows[f"{name}_floor"] = floored(rows[f"{name}_base"], FLOOR)
    modes, labels = MODES + ("floor",), {**LABELS, "floor": "shipped + floor"}
    seq1, seq2 = ([n for n, *_ in seqs.sequences(w)] for w in ("check", "check2"))
    group = {name: (lambda m, name=name: rows[f"{name}_{m}"]) for name in list(SETS) + list(SETS2)}
    group["seq"] = lambda m: [r for n in seq1 for r in rows[f"seq_{m}_{n}"]]
    group["seq2"] = lambda m: [r for n in seq2 for r in rows[f"seq_{m}_{n}"]]
    c: dict[str, dict[str, dict]] = {}
    print(HEAD)
    for name in ("a2", "b2", "seq2", "round1", "round2", "pooled"):
        parts = {"round1": ("a", "b", "seq"), "round2": ("a2", "b2", "seq2"),
                 "pooled": ("a", "b", "seq", "a2", "b2", "seq2")}.get(name, (name,))
        for m in modes:
            c.setdefault(name, {})[m] = s33.counts([r for part in parts for r in group[part](m)])
            print(line(name, labels[m], c[name][m]))
    print("  a2: " + SETS2["a2"][1] + "; b2: " + SETS2["b2"][1])
    print(f"  seq2: {len(seq2)} sequences of 40 frames ({seq2[0]} ... {seq2[-1]}; reports/floor_s34/sequences.py "
          "check2); round1: rule.txt's sets a, b and seq")
    print("  shipped + floor: the shipped bundle with confidence.min_valid 0.08 (sequences run; independent frames "
          "are the shipped rows with poses under 0.08 turned invalid, exact without a prior)")
    print()
    print("wrong valid poses of round 2 (set, frame, e_R, e_t, route, chamfer, confidence):")
    for m in modes:
        keyed = [(name, r) for name in SETS2 for r in rows[f"{name}_{m}"]]
        keyed += [(n, r) for n in seq2 + (seq1 if m == "floor" else []) for r in rows[f"seq_{m}_{n}"]]
        print_wrong(labels[m], 16, keyed)
    print()
    for m in modes:
        seq = group["seq"](m) + group["seq2"](m)
        print(f"sequences of both rounds, {labels[m]}: {sum('min_valid' in (r.get('detail') or '') for r in seq)} "
              f"poses refused by the floor; tracked valid {sum(bool(r['valid'] and r['tracked']) for r in seq)}")
    print()
    print("position-only frames, independent frames of both rounds:")
    for m in MODES:
        pos32.print_table(f"a+b+a2+b2 {labels[m]}", pos32.position_table(
            [r for name in list(SETS) + list(SETS2) for r in rows[f"{name}_{m}"]]))
    print()
    base, cand, floor = (c["pooled"][m] for m in modes)
    fails = [f"B1. valid poses > 90 deg off: {cand['flips']}"] if cand["flips"] else []
    fails += [f"B2. wrong {cand['wrong']} > {base['wrong']}"] if cand["wrong"] > base["wrong"] else []
    fails += ([f"B3. > 20 deg {cand['rotated']} > {base['rotated']} + 1"]
              if cand["rotated"] > base["rotated"] + 1 else [])
    fails += ([f"B4. within {cand['within']} < 1.10 x {base['within']}"]
              if cand["within"] < 1.10 * base["within"] else [])
    fails += [f"B5. valid {cand['valid']} < 0.90 x {base['valid']}"] if cand["valid"] < 0.90 * base["valid"] else []
    ind = list(SETS) + list(SETS2)
    t_base = pos32.position_table([r for name in ind for r in rows[f"{name}_base"]])["all"]
    t_cand = pos32.position_table([r for name in ind for r in rows[f"{name}_cand"]])["all"]
    fails += ([f"B6. position-only e_pos {t_cand['e_pos']:.3f} > {t_base['e_pos']:.3f} + 0.02"]
              if t_cand["e_pos"] > t_base["e_pos"] + 0.02 else [])
    fails += ([f"B6. position-only within tau {t_cand['within_tau']:.3f} < {t_base['within_tau']:.3f} - 0.03"]
              if t_cand["within_tau"] < t_base["within_tau"] - 0.03 else [])
    print("verdict B (rule2.txt): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    fails = [f"A1. valid poses > 90 deg off: {floor['flips']}"] if floor["flips"] else []
    fails += [f"A2. wrong {floor['wrong']} > {base['wrong']}"] if floor["wrong"] > base["wrong"] else []
    fails += [f"A3. > 20 deg {floor['rotated']} > {base['rotated']}"] if floor["rotated"] > base["rotated"] else []
    fails += ([f"A4. within {floor['within']} < 0.97 x {base['within']}"]
              if floor["within"] < 0.97 * base["within"] else [])
    fails += ([f"A5. valid {floor['valid']} < 0.85 x {base['valid']}"]
              if floor["valid"] < 0.85 * base["valid"] else [])
    print("verdict A (rule2.txt): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--round2"]:
        return round2(Path(argv[1]) if argv[1:] else Path("runs/s34"))
    runs = Path(argv[0]) if argv else Path("runs/s34")
    rows = pose_rows(runs, HERE / "rows.json.gz")
    stereo = stereo_metrics(runs)
    c = report(rows)
    print()
    details(rows)
    print()
    print("stereo over target pixels, the 100 test-split frames of tdrs640_s34a:")
    for m in MODES:
        s = stereo[m]
        print(f"  {LABELS[m]:<10} {s['frames']} frames  EPE {s['epe']:.3f} px  D1 {s['d1']:.2f} %  "
              f"bad-1 {s['bad1']:.2f} %  bad-3 {s['bad3']:.2f} %  RMSE {s['rmse']:.3f} px")
    print()
    base, cand = c["pooled"]["base"], c["pooled"]["cand"]
    print(f"pooled: valid {base['valid']} -> {cand['valid']} ({cand['valid'] / max(base['valid'], 1):.3f} x), "
          f"wrong {base['wrong']} -> {cand['wrong']}, > 20 deg {base['rotated']} -> {cand['rotated']}, "
          f"within {base['within']} -> {cand['within']} ({cand['within'] / max(base['within'], 1):.3f} x)")
    print(verdict(c, stereo, rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
