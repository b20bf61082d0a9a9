"""Session 41, exploration on spent views: two flip classifiers together (the shipped one and session 40's).

    python reports/flip_s41/ensemble_explore.py SAMPLES_PLAIN.npz SAMPLES_RESTYLED.npz -- BASE_CKPT OTHER_CKPT

The sample files are ``reports/tone_s38/classifier_val.py samples`` output of session 38's 400 validation views
(spent: session 40 judged its classifier on them). For each look, each combination below is decided the way the
runtime decides (p >= decide at the view and at the tone powers 2 and 1/2), and the table counts the decided views
with a right pose, the wrong ones among them and the pairs with neither pose right that were decided:

* ``base`` / ``other``: one classifier alone;
* ``both``: both decide the same side;
* ``other, base agrees >= q``: the other decides, and the base gives the same side at least q at every tone power
  (and the base's own decisions are kept);
* ``mean logit``: the two logits averaged, then decided.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tone_s38"))
from classifier_val import _model  # noqa: E402

DECIDES = (0.995, 0.999)
AGREE = (0.5, 0.9, 0.99)


def tone_logits(net, views: np.ndarray) -> np.ndarray:
    """(3, N) float64 logits at the view and at the tone powers (``TONE_POWERS``)."""
    from spacepose.flip_views import toned_views
    from spacepose.tools.train_flip import TONE_POWERS, batched_logits

    rows = [views] + [toned_views(views, g) for g in TONE_POWERS]
    return np.stack([batched_logits(net, v).astype(np.float64).reshape(-1) for v in rows])


def sides(logits: np.ndarray, p: float) -> np.ndarray:
    """+1 / -1 / 0: the side decided at p at every tone power, else 0."""
    cut = np.log(p / (1 - p))
    up = (logits >= cut).all(axis=0)
    down = (logits <= -cut).all(axis=0)
    return np.where(up, 1, np.where(down, -1, 0))


def main(sample_paths: list[str], ckpts: list[str]) -> int:
    from spacepose.tools.flip_data import load_samples

    nets = [_model(c) for c in ckpts]
    print(f"base {ckpts[0]}, other {ckpts[1]}")
    print("| look | decide | combination | decided | wrong | neither decided |")
    print("|---|---|---|---|---|---|")
    for look, path in zip(("as rendered", "restyled"), sample_paths):
        s = load_samples(path)
        la, lb = (tone_logits(n, s["views"]) for n in nets)
        one = s["labels"] != 0.5
        truth = np.where(s["labels"] > 0.5, 1, -1)
        for p in DECIDES:
            a, b = sides(la, p), sides(lb, p)
            combos = {"base": a, "other": b, "both": np.where(a == b, a, 0), "mean logit": sides((la + lb) / 2, p)}
            for q in AGREE:
                agree = sides(la, q)
                combos[f"other, base agrees >= {q}"] = np.where(a != 0, a, np.where(agree == b, b, 0))
            for name, side in combos.items():
                dec = one & (side != 0)
                wrong = dec & (side != truth)
                neither = (~one) & (side != 0)
                print(f"| {look} | {p} | {name} | {int(dec.sum())} | {int(wrong.sum())} | {int(neither.sum())} |")
    return 0


if __name__ == "__main__":
    args = sys.argv[1:]
    cut = args.index("--")
    sys.exit(main(args[:cut], args[cut + 1:]))
