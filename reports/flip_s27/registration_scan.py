"""Session 27: the valid poses the registration route decided on the spent single-frame sets of sessions 22-27,
each with the bundle of its day, and what a least classifier probability for that route would have refused
(gate R's choice, reports/flip_s27/gate_rule.txt; post hoc).

    python reports/flip_s27/registration_scan.py

Reads session 26's and 27's runs from runs/ where this session's machine still had them (runs/s26/*_default,
test_shipped26, unseen_shipped26; runs/s27/*_S but for its repeats of those two) and the committed rows of
sessions 22-24; run elsewhere it counts what is there (this session's output: registration_scan_output.txt). Run
from the repository root.
"""
import glob
import gzip
import json

from judge import FAR_DEG, wrong  # this folder: plan.txt's judge


def sources() -> list[str]:
    runs = set(glob.glob("runs/s26/*_default/pose_eval.json")) | set(glob.glob("runs/s27/*_S/pose_eval.json"))
    runs |= {"runs/s26/test_shipped26/pose_eval.json", "runs/s26/unseen_shipped26/pose_eval.json"}
    committed = set(glob.glob("reports/flip_s24/*_S.json.gz")) | set(glob.glob("reports/flip_s23/*_S.json.gz"))
    committed |= {"reports/flip_s22/big2700_shipped.json.gz"}
    repeats = {"runs/s27/test_S/pose_eval.json", "runs/s27/unseen_S/pose_eval.json"}   # = session 26's runs
    return sorted(p for p in (runs | committed) - repeats if "seq_" not in p)


def frames(path: str) -> list[dict]:
    try:
        with (gzip.open(path, "rt") if path.endswith(".gz") else open(path)) as fh:
            return json.load(fh)["frames"]
    except FileNotFoundError:
        return []


def main() -> None:
    n_sets, n_valid, regs = 0, 0, []
    for path in sources():
        valid = [r for r in frames(path) if r["valid"]]
        n_sets += bool(valid)
        n_valid += len(valid)
        name = path.split("/")[-2] if path.endswith("pose_eval.json") else path.split("/")[-1]
        regs += [(name, r) for r in valid if r["decided_by"] == "registration"]
    print(f"sets {n_sets}, valid poses {n_valid}, by the registration route {len(regs)}")
    for thr in (0.5, 0.7, 0.8, 0.9, 0.95, 0.99):
        gone = [r for _, r in regs if not r.get("flip_prob", float("nan")) >= thr]
        far = sum(r["e_R"] > FAR_DEG for r in gone)
        print(f"  least p {thr}: refuses {len(gone)}, of them wrong {sum(map(wrong, gone))}, > 90 deg {far}")
    for name, r in sorted(regs, key=lambda x: x[1].get("flip_prob", 2.0)):
        print(f"{name:28s} {r['frame']} p {r.get('flip_prob', float('nan')):.3f} e_R {r['e_R']:6.1f} "
              f"e_t {r['e_t']:.2f} chamfer {r['outline_chamfer_px']:.2f}")


if __name__ == "__main__":
    main()
