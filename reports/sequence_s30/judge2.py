"""Table and verdict of reports/sequence_s30/rule2.txt (prior_max_gap 2 with the coarse pass on every frame).

    python reports/sequence_s30/judge2.py [RUNS]

RUNS (default ``runs/s30``) holds ``sequence eval`` reports: for the fit sequences ``nopw_seq_fNN.json`` (gap 0,
the coarse pass on every frame) and ``gap2_seq_fNN.json`` (``--prior-max-gap 2``, run from commit 33bab31, whose
default is the coarse pass); for the check sequences (``python reports/sequence_s30/sequences.py check2``, run from
commit 23586c9) ``seq_dNN.json`` (that commit's default: gap 0, the coarse pass) and ``gap2_seq_dNN.json``; reported only, after both
verdicts, ``s29def_seq_dNN.json``: session 29's defaults (``--prior-window --prior-max-gap 0``), so that the two
changes together can be read against them on the same fresh scenes. When every run is
there, the frames are cut to the columns used here and written to ``rows2.json.gz`` beside this script; otherwise
that committed file is read.
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
sys.path.insert(0, str(HERE))
from _rows import compact_rows  # noqa: E402
from judge import HEAD, KEYS, _line, summary  # noqa: E402
from sequences import sequences  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402

MODES = {("fit", "gap 0"): "nopw_{}", ("fit", "gap 2"): "gap2_{}", ("check2", "gap 0"): "{}",
         ("check2", "gap 2"): "gap2_{}", ("check2", "s29 defaults"): "s29def_{}"}


def main(argv: list[str]) -> int:
    runs = Path(argv[0]) if argv else Path("runs/s30")
    files = {pattern.format(name): [runs / f"{pattern.format(name)}.json"]
             for (which, _), pattern in MODES.items() for name, *_ in sequences(which)}
    rows = compact_rows(files, HERE / "rows2.json.gz", KEYS, defaults={"roi": None})
    bundle = load_bundle(None, verify_graphs=False)
    results = {}
    print(HEAD)
    for (which, mode), pattern in MODES.items():
        frames = [r for name, *_ in sequences(which) for r in rows[pattern.format(name)]]
        results[which, mode] = summary(frames, bundle)
        print(_line(which, mode, results[which, mode]))
    print("(columns as in judge.py; the s29 defaults row is reported only: the previous pose's window and gap 0)")
    old, new = results["check2", "gap 0"], results["check2", "gap 2"]
    fails = []
    fails += [f"1. > 90 deg {new['flips']} > 0"] if new["flips"] > 0 else []
    fails += [f"2. wrong {new['wrong']} > {old['wrong']} + 1"] if new["wrong"] > old["wrong"] + 1 else []
    fails += [f"3. valid {new['valid']} < 1.05 x {old['valid']}"] if new["valid"] < 1.05 * old["valid"] else []
    fails += [f"4. within {new['within']} < {old['within']}"] if new["within"] < old["within"] else []
    fails += ([f"5. e_t mean {new['e_t_mean']:.3f} > {old['e_t_mean']:.3f} + 0.01"]
              if new["e_t_mean"] > old["e_t_mean"] + 0.01 else [])
    print()
    print("verdict (rule2.txt, the 16 check2 sequences, candidate = prior_max_gap 2): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
