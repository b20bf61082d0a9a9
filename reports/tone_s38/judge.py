"""Session 38: the clauses of reports/tone_s38/rule.txt (cand: the shipped bundle with flip_classifier.decide_tone_gamma
2.0) and rule2.txt (cand2: the shipped bundle with session 37's image-route gates); base: the shipped bundle.

    python reports/tone_s38/judge.py collect [MODE...]   # once: rows of runs/s38 -> compact files beside this file
    python reports/tone_s38/judge.py [--cand cand2]      # the clauses and the verdict, from the files beside this file

``collect`` cuts ``runs/s38/check_MODE_{plain,rest}.json.gz`` (``spacepose.tools.shard_eval`` rows) to the
columns read here and merges the ``sequence eval`` reports ``runs/s38/MODE_seq_z*.json`` into
``seq_MODE.json.gz`` (a row per frame, with its sequence's name); MODE: base and cand unless given.
"""
from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s38"
WRONG_T_M, WRONG_R_DEG, FAR_DEG = 0.5, 20.0, 90.0
WITHIN_T_M, WITHIN_R_DEG = 0.10, 2.0
BUNDLES = ("base", "cand")  # the pair judged; judge(cand2) swaps the second
KEYS = ("frame", "regime", "distance", "valid", "status", "confidence", "e_t", "e_R", "flip_prob", "outline_chamfer_px",
        "outline_margin_px", "depth_tolerance_m", "decided_by", "tracked", "position_valid", "e_pos")


def collect(modes: list[str], runs: Path = RUNS, out: Path = HERE, seq_glob: str = "seq_z*") -> None:
    """The rows of ``runs`` cut to :data:`KEYS` into ``out`` (module docstring); ``seq_glob``: the sequences' names."""
    from spacepose.tools.shard_eval import write_rows

    for b in modes or BUNDLES:
        for s in ("plain", "rest"):
            doc = json.loads(gzip.decompress((runs / f"check_{b}_{s}.json.gz").read_bytes()))
            doc["frames"] = [{k: r.get(k) for k in KEYS if k in r} for r in doc["frames"]]
            doc["cut_to"] = list(KEYS)
            write_rows(doc, out / f"check_{b}_{s}.json.gz")
        rows = []
        for path in sorted(runs.glob(f"{b}_{seq_glob}.json")):
            seq = path.stem[len(b) + 1:]
            rows += [{"seq": seq, **{k: r.get(k) for k in KEYS if k in r}}
                     for r in json.loads(path.read_text())["frames"]]
        if len({r["seq"] for r in rows}) != 24:
            raise SystemExit(f"{b}: {len({r['seq'] for r in rows})} sequences, want 24")
        write_rows({"frames": rows, "cut_to": ["seq", *KEYS]}, out / f"seq_{b}.json.gz")


def _load(name: str, folder: Path = HERE) -> list[dict]:
    return json.loads(gzip.decompress((folder / f"{name}.json.gz").read_bytes()))["frames"]


def _wrong(r: dict) -> bool:
    return bool(r["valid"]) and (r["e_t"] > WRONG_T_M or r["e_R"] > WRONG_R_DEG)


def _within(r: dict) -> bool:
    return bool(r["valid"]) and r["e_t"] <= WITHIN_T_M and r["e_R"] <= WITHIN_R_DEG


def _far(r: dict) -> bool:
    return bool(r["valid"]) and r["e_R"] > FAR_DEG


def _key(r: dict) -> tuple:
    return (r.get("seq", ""), r["frame"])


def sets(cand: str = "cand", folder: Path = HERE, restyled_prefix: str = "seq_zr"
         ) -> dict[str, dict[str, dict[tuple, dict]]]:
    """{set: {"base" | "cand": {(sequence, frame): row}}} for F, R, S and SR of the rows in ``folder``; "cand" holds
    ``cand``'s rows; sequences named ``restyled_prefix``... are SR."""
    out: dict = {}
    for b in BUNDLES:
        stem = cand if b == "cand" else b
        out.setdefault("F", {})[b] = {_key(r): r for r in _load(f"check_{stem}_plain", folder)}
        out.setdefault("R", {})[b] = {_key(r): r for r in _load(f"check_{stem}_rest", folder)}
        seq = _load(f"seq_{stem}", folder)
        out.setdefault("S", {})[b] = {_key(r): r for r in seq if not r["seq"].startswith(restyled_prefix)}
        out.setdefault("SR", {})[b] = {_key(r): r for r in seq if r["seq"].startswith(restyled_prefix)}
    for name, by in out.items():
        if by["base"].keys() != by["cand"].keys():
            raise SystemExit(f"{name}: base and cand rows are not of the same frames")
    return out


def table(data: dict, title: str) -> None:
    """Print ``title`` and a row per set and bundle: frames, valid, within, wrong, far, tracked valid."""
    print(title)
    print("| set | bundle | frames | valid | within | wrong | far | tracked valid |")
    print("|---|---|---|---|---|---|---|---|")
    for name, by in data.items():
        for b, rows in by.items():
            v = list(rows.values())
            print(f"| {name} | {b} | {len(v)} | {sum(bool(r['valid']) for r in v)} | {sum(map(_within, v))} | "
                  f"{sum(map(_wrong, v))} | {sum(map(_far, v))} | "
                  f"{sum(bool(r['valid'] and r.get('tracked')) for r in v)} |")


def _rule1_rest(data: dict, clauses: dict, valid) -> None:
    """rule.txt's V3 (the refused poses are the wrong ones) and V4 (the cost)."""
    refused = [(n, k, by["base"][k]) for n, by in data.items() for k, r in by["cand"].items()
               if by["base"][k]["valid"] and not r["valid"]]
    d_wrong = sum(_wrong(r) for _, _, r in refused)
    all_names = tuple(data)
    base_valid, base_wrong = pooled(data, all_names, "base", valid), pooled(data, all_names, "base", _wrong)
    share_d = d_wrong / max(len(refused), 1)
    share_b = base_wrong / max(base_valid, 1)
    print(f"V3: D = {len(refused)} poses base reports and cand refuses, {d_wrong} of them wrong "
          f"({100 * share_d:.1f} %); base: {base_wrong} wrong of {base_valid} valid ({100 * share_b:.2f} %)")
    for n, k, r in refused:
        print(f"    {n} {k[0]} {k[1]}: e_t {r['e_t']:.2f} m, e_R {r['e_R']:.1f} deg, {r['decided_by']}, "
              f"confidence {r['confidence']:.2f}" + (" WRONG" if _wrong(r) else ""))
    clauses["V3 the refused are the wrong"] = d_wrong >= 1 and share_d >= 2.0 * share_b
    v4 = []
    for names in (("F", "R"), ("S", "SR")):
        v = {b: pooled(data, names, b, valid) for b in BUNDLES}
        w = {b: pooled(data, names, b, _within) for b in BUNDLES}
        print(f"V4 {'+'.join(names)}: valid cand {v['cand']} vs base {v['base']} "
              f"({v['cand'] / max(v['base'], 1):.3f}); within cand {w['cand']} vs base {w['base']} "
              f"({w['cand'] / max(w['base'], 1):.3f})")
        v4.append(v["cand"] >= 0.94 * v["base"] and w["cand"] >= 0.94 * w["base"])
    clauses["V4 the cost"] = all(v4)


def pooled(data: dict, names: tuple[str, ...], b: str, test) -> int:
    """How many of bundle ``b``'s rows in the sets ``names`` of ``data`` (:func:`sets`) pass ``test``."""
    return sum(test(r) for n in names for r in data[n][b].values())


def clause_no_new_far(data: dict, clauses: dict, tag: str = "V1") -> None:
    """``tag``: no valid cand pose is far unless base's pose of the same frame is far too (printed, into
    ``clauses``). Sessions 38-40's rules share it."""
    new_far = [(n, k) for n, by in data.items() for k, r in by["cand"].items() if _far(r) and not _far(by["base"][k])]
    clauses[f"{tag} no new far pose"] = not new_far
    print(f"{tag}: cand's far poses that base does not report:", new_far)


def clause_no_more_wrong(data: dict, clauses: dict, tag: str = "V2") -> None:
    """``tag``: F+R pooled and S+SR pooled, cand's wrong poses at most base's (printed, into ``clauses``)."""
    ok = []
    for names in (("F", "R"), ("S", "SR")):
        w = {b: pooled(data, names, b, _wrong) for b in BUNDLES}
        print(f"{tag} {'+'.join(names)}: wrong cand {w['cand']} vs base {w['base']}")
        ok.append(w["cand"] <= w["base"])
    clauses[f"{tag} no more wrong"] = all(ok)


def print_verdict(clauses: dict, met: str) -> bool:
    """Print every clause and the verdict (``met`` when all hold); returns whether all hold."""
    for name, ok in clauses.items():
        print(f"{name}: {'holds' if ok else 'FAILS'}")
    all_hold = all(clauses.values())
    print("verdict:", met if all_hold else "NOT MET: nothing of it ships")
    return all_hold


def judge(cand: str = "cand") -> int:
    """rule.txt's clauses (``cand``) or rule2.txt's (``cand2``); prints them and the verdict."""
    data = sets(cand)
    table(data, f"base: the shipped bundle; cand: {cand}")

    valid = lambda r: bool(r["valid"])  # noqa: E731
    clauses = {}
    clause_no_new_far(data, clauses)
    clause_no_more_wrong(data, clauses)
    if cand == "cand":
        _rule1_rest(data, clauses, valid)
    else:
        v = {b: pooled(data, ("F", "R"), b, valid) for b in BUNDLES}
        w = {b: pooled(data, ("F", "R"), b, _within) for b in BUNDLES}
        ws = {b: pooled(data, ("S", "SR"), b, _within) for b in BUNDLES}
        print(f"V3 F+R: valid cand2 {v['cand']} vs base {v['base']} ({v['cand'] / max(v['base'], 1):.3f}); within "
              f"cand2 {w['cand']} vs base {w['base']} ({w['cand'] / max(w['base'], 1):.3f})")
        print(f"V4 S+SR: within cand2 {ws['cand']} vs base {ws['base']} ({ws['cand'] / max(ws['base'], 1):.3f})")
        clauses["V3 more poses"] = v["cand"] >= 1.02 * v["base"] and w["cand"] >= 1.02 * w["base"]
        clauses["V4 sequences keep theirs"] = ws["cand"] >= 0.98 * ws["base"]
    print_verdict(clauses, "MET: " + ("decide_tone_gamma 2.0" if cand == "cand" else "the two image gates")
                  + " may ship")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["collect"]:
        collect(sys.argv[2:])
    else:
        raise SystemExit(judge(sys.argv[2] if sys.argv[1:2] == ["--cand"] else "cand"))
