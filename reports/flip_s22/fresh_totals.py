"""Reproduces the session-22 figures quoted in README.md and runtime/bundles/default/MODEL_CARD.md from the
committed reports beside this script (no rendering, no evaluation; runs in a fresh clone in seconds):

    python reports/flip_s22/fresh_totals.py

1. the 2,700 fresh frames (``tdrs640_big``, seed 19) with the shipped bundle: valid share, wrong poses,
   poses > 90 deg off, mean/median errors of the valid poses, valid share per distance bin and per regime,
   and how many valid poses the flip classifier decided;
2. the 19 reference sequences: shipped bundle (round-4 candidate C) against the bundle before session 22 (S);
3. every pose the shipped bundle reported on fresh data of session 22 (single-frame sets and sequences e, f, g)
   and how many of them are > 90 deg off;
4. the tracked-outline analysis behind ``silhouette.track_needs_outline``: on the 39 sequences evaluated with
   the bundle before session 22, the tracked valid poses' outline chamfer for wrong and right poses.

Wrong: e_R > 20 deg or e_t > 0.5 m; far: e_R > 90 deg (a flip).
"""
import gzip
import json
import tarfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
S21 = HERE.parent / "flip_s21"
MAX_E_T, MAX_E_R, FLIP_DEG, CHAMFER_PX = 0.5, 20.0, 90.0, 1.5
REFERENCE = ["sun14", "penumbra20", "albedo12", "sun18", "mixed12", "sun16b", "albedo24b", "mixed30b",
             "penumbra15b"] + [f"c{i}" for i in range(1, 11)]


def gz_frames(name):
    with gzip.open(HERE / f"{name}.json.gz", "rt") as fh:
        return json.load(fh)["frames"]


def tar_frames(tar_path, member):
    with tarfile.open(tar_path) as tar:
        return json.load(tar.extractfile(member))["frames"]


def wrong(r):
    return r["e_R"] > MAX_E_R or r["e_t"] > MAX_E_T


def tally(frames):
    valid = [r for r in frames if r["valid"]]
    return dict(n=len(frames), valid=len(valid), wrong=sum(map(wrong, valid)),
                far=sum(r["e_R"] > FLIP_DEG for r in valid), tracked=sum(bool(r.get("tracked")) for r in valid))


def big_summary():
    frames = gz_frames("big2700_shipped")
    t = tally(frames)
    valid = [r for r in frames if r["valid"]]
    e_t = np.array([r["e_t"] for r in valid])
    e_r = np.array([r["e_R"] for r in valid])
    print(f"1. tdrs640_big, shipped bundle: {t['valid']} of {t['n']} valid ({100 * t['valid'] / t['n']:.1f} %), "
          f"{t['wrong']} wrong, {t['far']} > 90 deg; mean {e_t.mean():.3f} m / {e_r.mean():.2f} deg, "
          f"median {np.median(e_t):.3f} m / {np.median(e_r):.2f} deg; "
          f"{sum(r['decided_by'] == 'classifier' for r in valid)} decided by the flip classifier")
    for lo in (10, 20, 30, 40):
        rows = [r for r in frames if lo <= r["distance"] < lo + 10]
        print(f"   {lo}-{lo + 10} m: {sum(r['valid'] for r in rows)} of {len(rows)} valid "
              f"({100 * sum(r['valid'] for r in rows) / max(len(rows), 1):.0f} %)")
    for regime in sorted({r["regime"] for r in frames}):
        rows = [r for r in frames if r["regime"] == regime]
        print(f"   {regime}: {sum(r['valid'] for r in rows)} of {len(rows)} valid "
              f"({100 * sum(r['valid'] for r in rows) / len(rows):.0f} %)")


def reference_sequences():
    rounds = HERE / "sequences_rounds2to4.tar.gz"
    c = tally([r for n in REFERENCE for r in tar_frames(rounds, f"seq/{n}_C.json")])
    s = tally([r for n in REFERENCE for r in tar_frames(S21 / "sequences.tar.gz", f"old/{n}_default.json")])
    first5_c = tally([r for n in REFERENCE[:5] for r in tar_frames(rounds, f"seq/{n}_C.json")])
    first5_s = tally([r for n in REFERENCE[:5] for r in tar_frames(S21 / "sequences.tar.gz", f"old/{n}_default.json")])
    print(f"2. the 19 reference sequences ({c['n']} frames): shipped {c['valid']} valid ({c['tracked']} tracked), "
          f"{c['wrong']} wrong, {c['far']} > 90 deg; before session 22: {s['valid']} valid, {s['wrong']} wrong, "
          f"{s['far']} > 90 deg. The first five ({', '.join(REFERENCE[:5])}): {first5_c['valid']} of {first5_c['n']} "
          f"valid (before: {first5_s['valid']})")


def fresh_totals():
    rounds = HERE / "sequences_rounds2to4.tar.gz"
    singles = {"tdrs640_val7": gz_frames("val7_cand"), "tdrs1280_val2": gz_frames("v1280b_cand"),
               "tdrs640_val8": gz_frames("val8a_Cp") + gz_frames("val8b_Cp"), "tdrs1280_val3": gz_frames("v1280c_Cp"),
               "tdrs640_val9": gz_frames("val9a_Cp") + gz_frames("val9b_Cp"), "tdrs1280_val4": gz_frames("v1280d_Cp"),
               "tdrs640_big": gz_frames("big2700_shipped")}
    seqs = {p: [r for i in range(1, n + 1) for r in tar_frames(rounds, f"seq/{p}{i}_C.json")]
            for p, n in (("e", 10), ("f", 20), ("g", 20))}
    print("3. shipped bundle on session 22's fresh data: valid / > 90 deg")
    totals = []
    for label, group in (("single frames", singles), ("sequences", seqs)):
        parts = {k: tally(v) for k, v in group.items()}
        for k, t in parts.items():
            print(f"   {k:14s} {t['valid']:4d} / {t['far']}")
        v, f = sum(t["valid"] for t in parts.values()), sum(t["far"] for t in parts.values())
        totals.append((v, f))
        print(f"   {label}: {v} valid, {f} > 90 deg")
    print(f"   all: {sum(v for v, _ in totals)} valid, {sum(f for _, f in totals)} > 90 deg")


def tracked_chamfer():
    names = [(S21 / "sequences.tar.gz", f"old/{n}_default.json") for n in REFERENCE]
    names += [(S21 / "sequences.tar.gz", f"fresh/d{i}_default.json") for i in range(1, 11)]
    names += [(HERE / "sequences_e_round1.tar.gz", f"fresh_e/e{i}_default.json") for i in range(1, 11)]
    tracked = [r for tar, m in names for r in tar_frames(tar, m) if r["valid"] and r.get("tracked")]
    bad = [r for r in tracked if wrong(r)]
    good = [r for r in tracked if not wrong(r)]

    def high(rows):  # no outline fit (NaN) counts as failing the outline test
        return sum(not r["outline_chamfer_px"] <= CHAMFER_PX for r in rows)

    print(f"4. {len(names)} sequences, bundle before session 22: {len(tracked)} tracked valid poses; "
          f"{high(bad)} of {len(bad)} wrong and {high(good)} of {len(good)} right have outline chamfer "
          f"> {CHAMFER_PX} px or none")


if __name__ == "__main__":
    big_summary()
    reference_sequences()
    fresh_totals()
    tracked_chamfer()
