"""Session 37: the clauses of reports/wide_s37/rule.txt (cand: session 36's wide-look stereo graph with the gates
choose_gates chose for it) or rule2.txt (cand2: the shipped graph with the gates choose_gates chose for it) on the
check rows; base: the shipped bundle.

    python reports/wide_s37/judge.py [--cand cand2]
    python reports/wide_s37/judge.py --round2          # rule3.txt: cand2 on fresh sets, rounds pooled

Reads ``check_{cand,base}_{plain,rest}.json.gz`` (and for ``--round2`` ``check2_{cand2,base}_{plain,rest}.json.gz``)
beside this file (``spacepose.tools.shard_eval`` rows, cut by ``cut_rows.py``).
"""
from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
WRONG_T_M, WRONG_R_DEG, FAR_DEG = 0.5, 20.0, 90.0
WITHIN_T_M, WITHIN_R_DEG = 0.10, 2.0


def counts(rows: list[dict]) -> dict:
    valid = [r for r in rows if r["valid"]]
    return {"frames": len(rows), "valid": len(valid),
            "within": sum(r["e_t"] <= WITHIN_T_M and r["e_R"] <= WITHIN_R_DEG for r in valid),
            "wrong": sum(r["e_t"] > WRONG_T_M or r["e_R"] > WRONG_R_DEG for r in valid),
            "over20": sum(r["e_R"] > WRONG_R_DEG for r in valid), "far": sum(r["e_R"] > FAR_DEG for r in valid),
            "positions": sum(bool(r["position_valid"]) for r in rows),
            "e_t_mean": sum(r["e_t"] for r in valid) / max(len(valid), 1),
            "e_R_mean": sum(r["e_R"] for r in valid) / max(len(valid), 1),
            "wrong_list": [(r["frame"], round(r["e_t"], 2), round(r["e_R"], 1), round(r["confidence"], 2),
                            r["decided_by"]) for r in valid if r["e_t"] > WRONG_T_M or r["e_R"] > WRONG_R_DEG]}


def load(stem: str) -> list[dict]:
    return json.loads(gzip.decompress((HERE / f"{stem}.json.gz").read_bytes()))["frames"]


def round2() -> int:
    """rule3.txt's clauses."""
    rows = {(r, b, s): load(f"{'check' if r == 1 else 'check2'}_{b}_{s}")
            for r in (1, 2) for b in ("cand2", "base") for s in ("plain", "rest")}
    c = {key: counts(v) for key, v in rows.items()}
    print("| round | bundle | set | frames | valid | within | wrong | > 20 deg | > 90 deg | positions | e_t mean | e_R mean |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (r, b, s), k in c.items():
        print(f"| {r} | {b} | {s} | {k['frames']} | {k['valid']} | {k['within']} | {k['wrong']} | {k['over20']} | "
              f"{k['far']} | {k['positions']} | {k['e_t_mean']:.3f} m | {k['e_R_mean']:.2f} |")
    for key, k in c.items():
        if key[0] == 2 and k["wrong_list"]:
            print(f"wrong {key}: (frame, e_t, e_R, confidence, route) {k['wrong_list']}")
    pooled = {b: {m: sum(c[(r, b, s)][m] for r in (1, 2) for s in ("plain", "rest"))
                  for m in ("valid", "within", "wrong", "over20", "far")} for b in ("cand2", "base")}
    new, base = pooled["cand2"], pooled["base"]

    def far_frames(r: int, b: str, s: str) -> set[str]:
        return {x["frame"] for x in rows[(r, b, s)] if x["valid"] and x["e_R"] > FAR_DEG}

    added = {s: far_frames(2, "cand2", s) - far_frames(2, "base", s) for s in ("plain", "rest")}
    clauses = {
        "R1 round 2: no cand2 pose > 90 deg where base has none; pooled > 90 deg cand2 <= base": (
            not any(added.values()) and new["far"] <= base["far"]),
        "R2 pooled wrong cand2 <= base + 2, wrong share <= base + 0.5 points": (
            new["wrong"] <= base["wrong"] + 2
            and new["wrong"] / max(new["valid"], 1) <= base["wrong"] / max(base["valid"], 1) + 0.005),
        "R3 pooled > 20 deg cand2 <= base + 1": new["over20"] <= base["over20"] + 1,
        "R4 pooled valid >= 1.05 x base, within >= 1.03 x base": (
            new["valid"] >= 1.05 * base["valid"] and new["within"] >= 1.03 * base["within"]),
        "R5 round 2, each set: within >= 0.95 x base": all(
            c[(2, "cand2", s)]["within"] >= 0.95 * c[(2, "base", s)]["within"] for s in ("plain", "rest")),
    }
    print(f"round 2, cand2 poses > 90 deg where base has none: {added}")
    print(f"pooled (2,160 frames): cand2 {new}, base {base}")
    print(f"wrong share: cand2 {new['wrong'] / max(new['valid'], 1):.4f}, base {base['wrong'] / max(base['valid'], 1):.4f}")
    for name, held in clauses.items():
        print(f"{name}: {'holds' if held else 'FAILS'}")
    print("verdict:", "MET (ships after the sequence check, rule3.txt)" if all(clauses.values())
          else "NOT MET: nothing ships")
    return 0


def main(argv: list[str]) -> int:
    if "--round2" in argv:
        return round2()
    cand = argv[argv.index("--cand") + 1] if "--cand" in argv else "cand"
    c = {(b, s): counts(json.loads(gzip.decompress((HERE / f"check_{b}_{s}.json.gz").read_bytes()))["frames"])
         for b in (cand, "base") for s in ("plain", "rest")}
    print("| bundle | set | frames | valid | within | wrong | > 20 deg | > 90 deg | positions | e_t mean | e_R mean |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for (b, s), k in c.items():
        print(f"| {b} | {s} | {k['frames']} | {k['valid']} | {k['within']} | {k['wrong']} | {k['over20']} | {k['far']} "
              f"| {k['positions']} | {k['e_t_mean']:.3f} m | {k['e_R_mean']:.2f} |")
    for key, k in c.items():
        if k["wrong_list"]:
            print(f"wrong {key}: (frame, e_t, e_R, confidence, route) {k['wrong_list']}")
    pooled = {b: {m: c[(b, "plain")][m] + c[(b, "rest")][m] for m in ("valid", "within", "wrong", "over20", "far")}
              for b in (cand, "base")}
    new, base = pooled[cand], pooled["base"]
    if cand == "cand":      # rule.txt
        clauses = {
            "W1 no cand pose > 90 deg": new["far"] == 0,
            "W2 pooled wrong cand <= base": new["wrong"] <= base["wrong"],
            "W3 pooled > 20 deg cand <= base": new["over20"] <= base["over20"],
            "W4 restyled valid >= 1.10 x base, within >= base": (
                c[(cand, "rest")]["valid"] >= 1.10 * c[("base", "rest")]["valid"]
                and c[(cand, "rest")]["within"] >= c[("base", "rest")]["within"]),
            "W5 plain valid and within >= 0.95 x base": (
                c[(cand, "plain")]["valid"] >= 0.95 * c[("base", "plain")]["valid"]
                and c[(cand, "plain")]["within"] >= 0.95 * c[("base", "plain")]["within"]),
        }
    else:                   # rule2.txt
        clauses = {
            "V1 no cand2 pose > 90 deg": new["far"] == 0,
            "V2 pooled wrong cand2 <= base": new["wrong"] <= base["wrong"],
            "V3 pooled > 20 deg cand2 <= base": new["over20"] <= base["over20"],
            "V4 pooled valid >= 1.05 x base, within >= 1.03 x base": (
                new["valid"] >= 1.05 * base["valid"] and new["within"] >= 1.03 * base["within"]),
            "V5 each set within >= 0.95 x base": all(
                c[(cand, s)]["within"] >= 0.95 * c[("base", s)]["within"] for s in ("plain", "rest")),
        }
    print(f"pooled: {cand} {new}, base {base}")
    for name, held in clauses.items():
        print(f"{name}: {'holds' if held else 'FAILS'}")
    print("verdict:", "MET: ship" if all(clauses.values()) else "NOT MET: nothing ships")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
