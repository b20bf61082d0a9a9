"""Session 41, step B of plan.txt: the shipped flip classifier alone, and with session 40's as a second opinion.

    python reports/flip_s41/combination_gate.py SAMPLES_PLAIN.npz SAMPLES_RESTYLED.npz -- FIRST_CKPT SECOND_CKPT
    python reports/flip_s41/combination_gate.py --round 2 ...     # plan2.txt: agree 0.95, B1 on added decisions

The sample files are ``reports/tone_s38/classifier_val.py samples`` output of the first 400 frames of the fresh set
F and of its restyled copy R. The first graph decides a view as the runtime decides it (p >= 0.995 on one side at
the view and at the tone powers 2 and 1/2); where it does not, the second decides the side it gives at least 0.995
at the view and both tone powers, when the first gives that side at least 0.9 at the view and both tone powers
(``flip_classifier.second_file`` / ``second_agree_prob``). Prints per look the decided right-pose views, the wrong
ones among them and the decided pairs with neither pose right, then clauses B1 and B2 and the verdict.

Round 2 (plan2.txt) asks the first graph to agree at 0.95, and its B1 counts only the wrong and neither-pair
decisions the first graph alone does not make (round 1's B1 counted the first graph's own, and it failed on one).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tone_s38"))
from classifier_val import _model  # noqa: E402
from ensemble_explore import sides, tone_logits  # noqa: E402

DECIDE, RATIO = 0.995, 1.15
AGREE = {1: 0.9, 2: 0.95}


def main(sample_paths: list[str], ckpts: list[str], round_: int = 1) -> int:
    from spacepose.tools.flip_data import load_samples

    if len(sample_paths) != 2 or len(ckpts) != 2:
        raise SystemExit("give two sample files (as rendered, restyled) and two checkpoints (first, second)")
    first, second = (_model(c) for c in ckpts)
    agree = AGREE[round_]
    print(f"round {round_}: first {ckpts[0]}, second {ckpts[1]}; decide {DECIDE}, agree {agree}")
    print("| look | right-pose views | first: decided | wrong | neither decided | both: decided | wrong | "
          "neither decided |")
    print("|---|---|---|---|---|---|---|---|")
    ok = True
    verdicts = []
    for look, path in zip(("as rendered", "restyled"), sample_paths):
        s = load_samples(path)
        la, lb = tone_logits(first, s["views"]), tone_logits(second, s["views"])
        a = sides(la, DECIDE)
        combined = np.where(a != 0, a, np.where(sides(la, agree) == sides(lb, DECIDE), sides(lb, DECIDE), 0))
        one = s["labels"] != 0.5
        truth = np.where(s["labels"] > 0.5, 1, -1)
        counts = []
        for side in (a, combined):
            dec = one & (side != 0)
            counts.append((int(dec.sum()), int((dec & (side != truth)).sum()), int(((~one) & (side != 0)).sum())))
        print(f"| {look} | {int(one.sum())} | " + " | ".join(str(v) for c in counts for v in c) + " |")
        (d0, w0, n0), (d1, w1, n1) = counts
        if round_ == 2:      # only what the second graph adds: the first graph's own decisions stay as they are
            w1, n1 = w1 - w0, n1 - n0
        b1, b2 = w1 == 0 and n1 == 0, d1 >= RATIO * d0
        ok &= b1 and b2
        what = "no wrong, no neither-pair decided" + (" beyond the first's" if round_ == 2 else "")
        verdicts.append(f"{look}: B1 ({what}) {'holds' if b1 else 'fails'} ({w1} wrong, {n1} neither); B2 (decided "
                        f">= {RATIO} x first) {'holds' if b2 else 'fails'} ({d1} against {d0}, x{d1 / max(d0, 1):.3f})")
    print("\n".join(verdicts))
    print("B: go on to the rule (C)" if ok else "B: not met; nothing ships")
    return 0


if __name__ == "__main__":
    args = sys.argv[1:]
    round_ = int(args[1]) if args[:1] == ["--round"] else 1
    args = args[2:] if args[:1] == ["--round"] else args
    cut = args.index("--")
    sys.exit(main(args[:cut], args[cut + 1:], round_))
