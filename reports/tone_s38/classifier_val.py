"""Session 38: the flip classifier alone, on the same validation views as rendered and restyled.

    python reports/tone_s38/classifier_val.py samples DATASET OUT.npz [--limit 400]   # views, as train-flip's val
    python reports/tone_s38/classifier_val.py table SAMPLES.npz... -- CKPT...        # the metrics per checkpoint

``samples`` draws one view per frame of DATASET (all splits; the first ``limit`` frames), as ``train-flip --val``
does (seed 39, a quarter with neither pose right), with the shipped bundle's silhouette samples. A restyled copy of
the dataset (``python -m spacepose.tools.restyle``) gives the same poses, frames and outlines with another look, so
the two tables differ only by the look. ``table`` prints ``spacepose.tools.train_flip.evaluate``'s metrics for every
checkpoint (``train-flip``'s ``last.pt`` or ``spacepose recover-checkpoint``'s rebuild of a shipped graph):
accuracy, ``decided`` (share decided at 0.995), ``tone_kept`` (of those, the share still decided the same way with the
grey plane raised to 2 and 1/2), ``sure_error`` (error among p >= 0.9) and ``neither_sure``, and the decisions at 0.995
that are wrong (or made where neither pose is right); and, for two sample
files given (as rendered, restyled), how often a decision at 0.995 turns to the other side or to undecided.
"""
from __future__ import annotations

import sys

import numpy as np

SEED, NEITHER = 39, 0.25


def samples(dataset: str, out: str, limit: int) -> None:
    from spacepose.bundle import load_bundle
    from spacepose.tools.flip_data import FlipSampleConfig, make_flip_samples, save_samples

    bundle = load_bundle(None, verify_graphs=False)
    s = make_flip_samples(dataset, bundle.silhouette_points, bundle.centre, split=None, per_frame=1, seed=SEED,
                          config=FlipSampleConfig(size=128, neither_prob=NEITHER), limit=limit)
    save_samples(s, out, {"dataset": dataset, "split": None, "per_frame": 1, "seed": SEED, "neither_prob": NEITHER,
                          "size": 128, "limit": limit})


def _model(path: str):
    from spacepose.export.recover import freeze_batchnorm
    from spacepose.models.flip_net import FlipNet, FlipNetConfig
    from spacepose.tools.training_common import load_checkpoint

    ckpt = load_checkpoint(path, kind="flip")
    net = FlipNet(FlipNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in ckpt["net_config"].items()}))
    net.load_state_dict(ckpt["model"])
    if ckpt.get("folded_bn"):
        freeze_batchnorm(net)
    return net.eval()


def table(sample_paths: list[str], ckpts: list[str]) -> None:
    import torch

    from spacepose.tools.flip_data import load_samples
    from spacepose.tools.train_flip import DECIDE, evaluate

    sets = [load_samples(p) for p in sample_paths]
    print("| checkpoint | samples | accuracy | decided | tone_kept | sure_error | neither_sure |")
    print("|---|---|---|---|---|---|---|")
    sides = {}
    for ckpt in ckpts:
        net = _model(ckpt)
        for path, s in zip(sample_paths, sets):
            m = evaluate(net, s["views"], s["labels"], s["regime"])["all"]
            print(f"| {ckpt} | {path} | {m['accuracy']:.3f} | {m['decided']:.3f} | {m['tone_kept']:.3f} | "
                  f"{m['sure_error']:.3f} | {m.get('neither_sure', float('nan')):.3f} |")
            with torch.no_grad():
                logit = torch.cat([net(torch.from_numpy(s["views"][i:i + 128]))
                                   for i in range(0, len(s["views"]), 128)]).numpy()
            p = 1.0 / (1.0 + np.exp(-logit.astype(np.float64)))
            side = sides[(ckpt, path)] = np.where(p >= DECIDE, 1, np.where(p <= 1.0 - DECIDE, -1, 0))
            one = s["labels"] != 0.5
            truth = np.where(s["labels"] > 0.5, 1, -1)
            decided = one & (side != 0)
            print(f"|  | decided at {DECIDE} with a right pose among the two: {int(decided.sum())}, of them wrong: "
                  f"{int((decided & (side != truth)).sum())}; with neither right: {int(((~one) & (side != 0)).sum())} "
                  "decided | | | | |")
    if len(sets) == 2:
        same = np.array_equal(sets[0]["labels"], sets[1]["labels"])
        print(f"look change ({sample_paths[0]} -> {sample_paths[1]}; same labels: {same}):")
        for ckpt in ckpts:
            a, b = sides[(ckpt, sample_paths[0])], sides[(ckpt, sample_paths[1])]
            print(f"  {ckpt}: decided {int((a != 0).sum())} -> {int((b != 0).sum())}; of those decided as rendered, "
                  f"{int(((a != 0) & (b == -a)).sum())} turn to the other side and {int(((a != 0) & (b == 0)).sum())} "
                  "to undecided")


if __name__ == "__main__":
    if sys.argv[1] == "samples":
        samples(sys.argv[2], sys.argv[3], int(sys.argv[5]) if sys.argv[4:5] == ["--limit"] else 400)
    else:
        cut = sys.argv.index("--")
        table(sys.argv[2:cut], sys.argv[cut + 1:])
