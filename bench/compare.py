#!/usr/bin/env python3
"""compare.py [options] REF.csv SURFACES.csv: the error of a solution (hrad's surfaces.csv)
against a path-traced reference (bench/ptref, or the verify.csv of `hrad --verify`): per-polygon
relative error |B - R| / |R| over RGB, its area-weighted RMS over non-emitting polygons with a
non-zero reference, the worst polygon, and the reference's own noise (area-weighted RMS of
|se| / |R|).
Prints one line:
  rms WORST_ID worst noise  (as percentages)
Numbers may be decimal or C99 hexadecimal floats (surfaces.csv under HRAD_TEST_EXACT=1).

Options:
  -v               a line per polygon as well
  --max-noise X    only the polygons whose reference noise is at most X (a fraction, e.g. 0.05):
                   for references too noisy for their smallest polygons (the conference room at
                   3,000 paths a polygon). The line then has a fifth field, the error with the
                   reference's noise removed in quadrature, sqrt(rms^2 - noise^2), and a sixth,
                   the area compared.
  --by-material    after the line, one per material (reference files with a 'material' column):
                   area, share of the summed squared error, RMS error (noise removed), mean
                   signed error (area-weighted, + too bright), polygons; largest share first."""
import argparse, csv, math, sys


def num(t):
    return float.fromhex(t) if 'x' in t or 'X' in t else float(t)


def main():
    ap = argparse.ArgumentParser(usage=__doc__.split(':')[0])
    ap.add_argument('ref')
    ap.add_argument('surfaces')
    ap.add_argument('-v', action='store_true', dest='verbose')
    ap.add_argument('--max-noise', type=float)
    ap.add_argument('--by-material', action='store_true')
    opt = ap.parse_args()
    verbose, by_mat, max_noise = opt.verbose, opt.by_material, opt.max_noise
    ref = {int(r['id']): r for r in csv.DictReader(open(opt.ref))}
    sol = {int(r['id']): r for r in csv.DictReader(open(opt.surfaces))}
    sw = se2 = sn2 = 0.0
    worst, wid = 0.0, -1
    mats = {}
    for pid, r in ref.items():
        if int(r['emitter']) or pid not in sol:
            continue
        R = [num(r['ref_' + c]) for c in 'rgb']
        S = [num(r['se_' + c]) for c in 'rgb']
        B = [num(sol[pid][c]) for c in 'rgb']
        nr = math.sqrt(sum(x * x for x in R))
        if nr <= 0:
            continue
        n = math.sqrt(sum(x * x for x in S)) / nr
        if max_noise is not None and n > max_noise:
            continue
        e = math.sqrt(sum((b - x) ** 2 for b, x in zip(B, R))) / nr
        a = num(r['area'])
        sw += a
        se2 += a * e * e
        sn2 += a * n * n
        if e > worst:
            worst, wid = e, pid
        sgn = sum(b - x for b, x in zip(B, R))
        if by_mat:
            m = mats.setdefault(r.get('material', '?'),
                                {'area': 0.0, 'e2': 0.0, 'n2': 0.0, 'signed': 0.0, 'n': 0})
            m['area'] += a
            m['e2'] += a * e * e
            m['n2'] += a * n * n
            m['signed'] += a * sgn / sum(R)
            m['n'] += 1
        if verbose:
            sign = '+' if sgn > 0 else '-'
            print(f"{pid:5d} area {a:9.4g}  err {100*e:7.3f}% {sign}  noise {100*n:6.3f}%")
    if sw <= 0:
        sys.exit("compare.py: no polygon to compare")
    rms, noise = math.sqrt(se2 / sw), math.sqrt(sn2 / sw)
    line = f"{100*rms:.3f} {wid} {100*worst:.3f} {100*noise:.3f}"
    if max_noise is not None:
        line += f" {100*math.sqrt(max(0.0, rms * rms - noise * noise)):.3f} {sw:.6g}"
    print(line)
    if by_mat:
        tot = sum(m['e2'] for m in mats.values())
        for name, m in sorted(mats.items(), key=lambda kv: -kv[1]['e2']):
            share = 100 * m['e2'] / tot if tot > 0 else 0
            print(f"{name:20s} area {m['area']:9.4g}  share {share:6.2f}%  "
                  f"rms {100*math.sqrt(max(0.0, m['e2'] - m['n2']) / m['area']):7.3f}%  "
                  f"signed {100*m['signed']/m['area']:+7.3f}%  n {m['n']}")


main()
