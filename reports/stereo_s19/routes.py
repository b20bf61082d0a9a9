"""Infer the decision route of valid rows of shipped-gate eval reports (rows made before decided_by)."""
import gzip, json, sys, math
def load(p):
    with (gzip.open if p.endswith('.gz') else open)(p, 'rt') as f:
        return json.load(f)['frames']
def route(r):
    if r.get('decided_by'): return r['decided_by']
    c, m = r['outline_chamfer_px'], r['outline_margin_px']
    s, px, bg = r['outline_image_score'], r['outline_image_pixels'], r['outline_image_background']
    if c == c and c <= 1.5 and m >= 0.5: return 'outline'
    if c == c and c <= 2.0 and m >= 0.2 and s == s and s >= 0.1 and px >= 16 and bg <= 0.02: return 'image'
    return 'registration'
wrong = lambda r: r['e_R'] > 20 or r['e_t'] > 0.5
for p in sys.argv[1:]:
    rows = [r for r in load(p) if r['valid']]
    out = {}
    for r in rows:
        k = route(r); o = out.setdefault(k, [0, 0, []])
        o[0] += 1; o[1] += wrong(r)
        if k == 'registration': o[2].append((round(r['outline_chamfer_px'], 2), round(r['flip_margin'], 3), 'W' if wrong(r) else 'ok'))
    print(p, {k: (v[0], v[1]) for k, v in out.items()})
    if 'registration' in out: print('   reg rows (chamfer, margin, ok?):', sorted(out['registration'][2]))
