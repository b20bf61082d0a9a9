"""Session 37: the clauses of reports/wide_s37/rule.txt (cand: session 36's wide-look stereo graph with the gates
choose_gates chose for it) or rule2.txt (cand2: the shipped graph with the gates choose_gates chose for it) on the
check rows; base: the shipped bundle.

    python reports/wide_s37/judge.py [--cand cand2]

Reads ``check_{cand,base}_{plain,rest}.json.gz`` beside this file (``spacepose.tools.shard_eval`` rows).
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


def main(argv: list[str]) -> int:
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
