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
import csv, math, sys


def num(t):
    return float.fromhex(t) if 'x' in t or 'X' in t else float(t)


def main():
    argv = sys.argv[1:]
    verbose = '-v' in argv
    by_mat = '--by-material' in argv
    max_noise = None
    args = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == '--max-noise':
            max_noise = float(argv[i + 1])
            i += 2
            continue
        if not a.startswith('-'):
            args.append(a)
        i += 1
    if len(args) != 2:
        sys.exit(__doc__)
    ref = {int(r['id']): r for r in csv.DictReader(open(args[0]))}
    sol = {int(r['id']): r for r in csv.DictReader(open(args[1]))}
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
            m = mats.setdefault(r.get('material', '?'), [0.0, 0.0, 0.0, 0, 0.0])
            m[0] += a
            m[1] += a * e * e
            m[4] += a * n * n
            m[2] += a * sgn / sum(R) if sum(R) > 0 else 0
            m[3] += 1
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
        tot = sum(m[1] for m in mats.values())
        for name, m in sorted(mats.items(), key=lambda kv: -kv[1][1]):
            share = 100 * m[1] / tot if tot > 0 else 0
            print(f"{name:20s} area {m[0]:9.4g}  share {share:6.2f}%  "
                  f"rms {100*math.sqrt(max(0.0, m[1] - m[4]) / m[0]):7.3f}%  "
                  f"signed {100*m[2]/m[0]:+7.3f}%  n {m[3]}")


main()
