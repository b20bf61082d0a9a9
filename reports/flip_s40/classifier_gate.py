"""Session 40, step B of plan.txt: flip classifiers alone, decided the way the runtime decides since session 39.

    python reports/flip_s40/classifier_gate.py SAMPLES_PLAIN.npz SAMPLES_RESTYLED.npz -- BASE_CKPT CAND_CKPT
    python reports/flip_s40/classifier_gate.py --decide P ...     # exploration only: another decide_prob for both

The sample files are ``reports/tone_s38/classifier_val.py samples`` output (one view per frame of a dataset and of
its restyled copy). A view is *decided* when p >= 0.995 on one side at the view and at the view's grey plane raised
to 2 and to 1/2 (``flip_classifier.decide_tone_gamma`` 2; :func:`spacepose.flip_views.toned_views`). Prints, per
checkpoint and look: views with a right pose among the two, decided ones, wrong ones among them, and pairs with
neither pose right that were decided; then clauses B1 (no wrong decision, no neither-pair decided) and B2 (the
candidate decides at least 1.15 x the base's right-pose views) of plan.txt, per look.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tone_s38"))
from classifier_val import _model  # noqa: E402

DECIDE, RATIO = 0.995, 1.15


def runtime_sides(net, views: np.ndarray, decide: float = DECIDE) -> np.ndarray:
    """+1 / -1 where the runtime's tone check decides pose A / pose B of each view, 0 where it does not
    (:func:`spacepose.tools.train_flip.held_decisions` on float64 logits)."""
    from spacepose.flip_views import toned_views
    from spacepose.tools.train_flip import TONE_POWERS, batched_logits, held_decisions

    def logits(v: np.ndarray) -> np.ndarray:
        return batched_logits(net, v).astype(np.float64).reshape(-1)

    _, side, holds = held_decisions(logits(views), [logits(toned_views(views, g)) for g in TONE_POWERS], decide)
    return np.where(holds, side, 0)


def main(sample_paths: list[str], ckpts: list[str], decide: float = DECIDE) -> int:
    from spacepose.tools.flip_data import load_samples

    if len(sample_paths) != 2 or len(ckpts) != 2:
        raise SystemExit("give two sample files (as rendered, restyled) and two checkpoints (base, candidate)")
    counts = {}
    print(f"decide_prob {decide}")
    print("| checkpoint | look | right-pose views | decided | of them wrong | neither-pairs decided |")
    print("|---|---|---|---|---|---|")
    for ckpt in ckpts:
        net = _model(ckpt)
        for look, path in zip(("as rendered", "restyled"), sample_paths):
            s = load_samples(path)
            side = runtime_sides(net, s["views"], decide)
            one = s["labels"] != 0.5
            truth = np.where(s["labels"] > 0.5, 1, -1)
            decided = one & (side != 0)
            wrong = decided & (side != truth)
            neither = (~one) & (side != 0)
            counts[(ckpt, look)] = (int(decided.sum()), int(wrong.sum()), int(neither.sum()))
            print(f"| {ckpt} | {look} | {int(one.sum())} | {int(decided.sum())} | {int(wrong.sum())} | "
                  f"{int(neither.sum())} |")
    base, cand = ckpts
    ok = True
    for look in ("as rendered", "restyled"):
        d0 = counts[(base, look)][0]
        d1, w1, n1 = counts[(cand, look)]
        b1 = w1 == 0 and n1 == 0
        b2 = d1 >= RATIO * d0
        ok &= b1 and b2
        print(f"{look}: B1 (no wrong, no neither-pair decided) {'holds' if b1 else 'fails'} ({w1} wrong, {n1} "
              f"neither); B2 (decided >= {RATIO} x base) {'holds' if b2 else 'fails'} ({d1} against {d0}, "
              f"x{d1 / max(d0, 1):.3f})")
    print("B: go on to a rule (C)" if ok else "B: not met; nothing ships")
    return 0


if __name__ == "__main__":
    args = sys.argv[1:]
    p = float(args[1]) if args[:1] == ["--decide"] else DECIDE
    args = args[2:] if args[:1] == ["--decide"] else args
    cut = args.index("--")
    sys.exit(main(args[:cut], args[cut + 1:], p))
