"""The sequences of session 38's check (reports/tone_s38/rule.txt).

    python reports/tone_s38/sequences.py render        # render + restyle commands
    python reports/tone_s38/sequences.py eval MODE...  # eval commands (base: the shipped bundle; else /tmp/s38/bundles/MODE)

12 sequences seq_z00..seq_z11, seeds 3811-3822, on session 30's grids (reports/sequence_s30/sequences.py), 40
frames at 640x480 on the paper rig; their restyled copies seq_zr00..seq_zr11 (restyle seeds 3831-3842, a style per
frame). Reports go to ``runs/s38/<mode>_<name>.json``.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "sequence_s30"))
import sequences as s30  # noqa: E402

s30.SETS.setdefault("check_s38", (3811, 12, "seq_z"))
RESTYLE_SEED = 3831


def sequences() -> list[tuple[str, int, int, str, int]]:
    """(name, seed, distance, regime, rate) of every plain sequence."""
    return s30.sequences("check_s38")


def commands(what: str, modes: list[str], plain: list[tuple[str, int, int, str, int]], *, prefixes: tuple[str, str],
             restyle_seed: int, session: str) -> list[str]:
    """The render-and-restyle command (``what`` "render") or the eval commands (else: one per folder and mode; base:
    the shipped bundle, else ``/tmp/<session>/bundles/<mode>``, reports to ``runs/<session>/``) of the ``plain``
    sequences (:func:`sequences`) and their restyled copies (``prefixes``: the plain names' prefix and the restyled
    copies' in its place; restyle seeds from ``restyle_seed``)."""
    out = []
    for i, (name, seed, distance, regime, rate) in enumerate(plain):
        restyled = name.replace(*prefixes)
        if what == "render":
            out.append(f"python -m spacepose.tools.sequence render data/{name} --frames 40 --distance {distance} "
                       f"--rate {rate} --regime {regime} --seed {seed} && python -m spacepose.tools.restyle "
                       f"data/{name} data/{restyled} --seed {restyle_seed + i} --split test")
            continue
        for folder in (name, restyled):
            for mode in modes:
                bundle = "" if mode == "base" else f" --bundle /tmp/{session}/bundles/{mode}"
                out.append(f"python -m spacepose.tools.sequence eval data/{folder} --threads 1{bundle} "
                           f"--json runs/{session}/{mode}_{folder}.json")
    return out


def check_main(argv: list[str], set_name: str, first_seed: int, prefix: str, restyle_seed: int, session: str) -> int:
    """Print :func:`commands` (``argv``: ``render``, or ``eval MODE...``) for a check set of 12 sequences on
    session 30's grids: ``prefix``00.. (seeds from ``first_seed``; registered in session 30's sets as ``set_name``)
    and their restyled copies ``prefix``r00.. (restyle seeds from ``restyle_seed``); reports to ``runs/<session>/``.
    Sessions 39 and 40 call it for their own sets."""
    s30.SETS.setdefault(set_name, (first_seed, 12, prefix))
    what, modes = (argv[0] if argv else "render"), argv[1:] or ["base"]
    print("\n".join(commands(what, modes, s30.sequences(set_name), prefixes=(prefix, prefix + "r"),
                             restyle_seed=restyle_seed, session=session)))
    return 0


def main(argv: list[str]) -> int:
    return check_main(argv, "check_s38", 3811, "seq_z", RESTYLE_SEED, "s38")


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
