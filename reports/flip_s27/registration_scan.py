"""Session 27: the valid poses the registration route decided on the spent single-frame sets of sessions 22-27,
each with the bundle of its day, and what a least classifier probability for that route would have refused
(gate R's choice, reports/flip_s27/gate_rule.txt; post hoc).

    python reports/flip_s27/registration_scan.py

Reads session 26's and 27's runs from runs/ where this session's machine still had them (runs/s26/*_default,
test_shipped26, unseen_shipped26; runs/s27/*_S) and the committed rows of sessions 22-24; run elsewhere it counts
what is there. Run from the repository root.
"""
import json,gzip,glob
srcs = sorted(set(glob.glob("runs/s26/*_default/pose_eval.json")) | {"runs/s26/test_shipped26/pose_eval.json","runs/s26/unseen_shipped26/pose_eval.json"}
        | set(glob.glob("runs/s27/*_S/pose_eval.json")) | set(glob.glob("reports/flip_s24/*_S.json.gz"))
        | set(glob.glob("reports/flip_s23/*_S.json.gz")) | {"reports/flip_s22/big2700_shipped.json.gz"})
tot_valid=0; regs=[]
for p in srcs:
    d=json.load(gzip.open(p,'rt') if p.endswith('.gz') else open(p))["frames"]
    if "seq_" in p: continue
    v=[r for r in d if r["valid"]]; tot_valid+=len(v)
    for r in v:
        if r["decided_by"]=="registration": regs.append((p.split('/')[-2] if p.endswith('pose_eval.json') else p.split('/')[-1], r))
print("sets",len(srcs),"valid",tot_valid,"registration-route",len(regs))
for thr in (0.5,0.7,0.8,0.9,0.95,0.99):
    ref=[r for _,r in regs if not r.get("flip_prob",float('nan'))>=thr]
    print(thr,"refused",len(ref),"wrong among them",sum(r["e_R"]>20 or r["e_t"]>0.5 for r in ref),"flips",sum(r["e_R"]>90 for r in ref))
for n,r in sorted(regs,key=lambda x:x[1].get("flip_prob",2)):
    print(f"{n:28s} {r['frame']} p {r.get('flip_prob',float('nan')):.3f} eR {r['e_R']:6.1f} et {r['e_t']:.2f} ch {r['outline_chamfer_px']:.2f}")
