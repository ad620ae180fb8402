#!/usr/bin/env python3
"""compare.py REF.csv SURFACES.csv: the error of a solution (hrad's surfaces.csv) against a
path-traced reference (bench/ptref): per-polygon relative error |B - R| / |R| over RGB, its
area-weighted RMS over non-emitting polygons with a non-zero reference, the worst polygon, and
the reference's own noise (area-weighted RMS of |se| / |R|). Prints one line:
  rms WORST_ID worst noise  (as percentages)
With -v, a line per polygon."""
import csv, math, sys

def main():
    args = [a for a in sys.argv[1:] if not a.startswith('-')]
    verbose = '-v' in sys.argv
    ref = {int(r['id']): r for r in csv.DictReader(open(args[0]))}
    sol = {int(r['id']): r for r in csv.DictReader(open(args[1]))}
    sw = se2 = sn2 = 0.0
    worst, wid = 0.0, -1
    for pid, r in ref.items():
        if int(r['emitter']) or pid not in sol:
            continue
        R = [float(r['ref_' + c]) for c in 'rgb']
        S = [float(r['se_' + c]) for c in 'rgb']
        B = [float(sol[pid][c]) for c in 'rgb']
        nr = math.sqrt(sum(x * x for x in R))
        if nr <= 0:
            continue
        e = math.sqrt(sum((b - x) ** 2 for b, x in zip(B, R))) / nr
        n = math.sqrt(sum(x * x for x in S)) / nr
        a = float(r['area'])
        sw += a
        se2 += a * e * e
        sn2 += a * n * n
        if e > worst:
            worst, wid = e, pid
        if verbose:
            sgn = sum(b - x for b, x in zip(B, R))
            print(f"{pid:5d} area {a:9.4g}  err {100*e:7.3f}% {'+' if sgn > 0 else '-'}  noise {100*n:6.3f}%")
    print(f"{100*math.sqrt(se2/sw):.3f} {wid} {100*worst:.3f} {100*math.sqrt(sn2/sw):.3f}")

main()
