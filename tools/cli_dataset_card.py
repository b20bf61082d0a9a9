"""``spacepose dataset-card DATASET --out DIR``: distributions, Fig. 11/12 plots, contact sheets."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "print a dataset's distributions and save Fig. 11/12-style plots and per-regime contact sheets"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path, help="dataset folder written by `spacepose render`")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default DATASET/card)")
    parser.add_argument("--per-regime", type=int, default=8, help="frames per contact sheet")


def run(args: argparse.Namespace) -> int:
    from spacepose.tools import dataset_card

    labels = dataset_card.read_labels(args.dataset)
    out = args.out or args.dataset / "card"
    summary = dataset_card.summarise(labels)
    print(dataset_card.format_summary(summary))
    written = dataset_card.plot_distributions(labels, out)
    written += dataset_card.contact_sheets(args.dataset, labels, out, per_regime=args.per_regime)
    (out / "card.json").write_text(json.dumps(summary, indent=2))
    for path in written:
        print(f"wrote {path}")
    return 0
