#!/usr/bin/env bash
# Accuracy per second: the error of hrad against a path-traced reference as the quality setting
# rises (BF_low = A_e), beside the path tracer's own error at the same time.
#   bash bench/accuracy.sh BUILD_DIR [OUT_DIR]
# Scenes: $ACC_SCENES (default "cornell room museum"). For each scene:
#   1. a reference: build/bench/ptref SCENE N (N = $ACC_REF_PATHS, per scene below), cached in
#      OUT/ref-SCENE.csv (delete it to recompute);
#   2. hrad at BF_low = A_e in $ACC_QUALITY (seconds: stats.json time_s.total, all cores);
#   3. the path tracer alone with increasing paths per polygon (another seed), timed the same way;
# then the area-weighted RMS error of every run (bench/compare.py) into OUT/accuracy.csv and one
# gnuplot picture per scene, OUT/accuracy-SCENE.png (error against time, log-log).
set -eu
build=$(cd "$1" && pwd)
here=$(cd "$(dirname "$0")/.." && pwd)
out=${2:-$build/bench}
mkdir -p "$out"
hrad=$build/hrad
ptref=$build/bench/ptref
cmp=$here/bench/compare.py
scenes=${ACC_SCENES:-cornell room museum}
quality=${ACC_QUALITY:-1e-2 3e-3 1e-3 3e-4}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

ref_paths() { case $1 in museum) echo "${ACC_REF_MUSEUM:-50000}" ;; *) echo "${ACC_REF_PATHS:-4000000}" ;; esac; }
pt_paths() { case $1 in museum) echo "${ACC_PT_MUSEUM:-500 2000 8000}" ;; *) echo "${ACC_PT_PATHS:-10000 40000 160000 640000}" ;; esac; }
quality_of() { case $1 in museum) echo "${ACC_QUALITY_MUSEUM:-1e-3 3e-4 1e-4}" ;; *) echo "$quality" ;; esac; }

echo "scene,method,setting,seconds,rms_pct,worst_id,worst_pct,ref_noise_pct,elements,links" > "$out/accuracy.csv"
for s in $scenes; do
  ref=$out/ref-$s.csv
  if [ ! -s "$ref" ]; then
    echo "accuracy: $s reference, $(ref_paths "$s") paths per polygon" >&2
    "$ptref" "$s" "$(ref_paths "$s")" "$ref" 7
  fi
  for q in $(quality_of "$s"); do
    "$hrad" --quiet --bf-low "$q" -o "$tmp/h" "$s"
    secs=$(sed -n 's/.*"total": \([0-9.e+-]*\)}.*/\1/p' "$tmp/h/stats.json")
    el=$(sed -n 's/^ *"elements": \([0-9]*\),/\1/p' "$tmp/h/stats.json")
    li=$(sed -n 's/^ *"links": \([0-9]*\),/\1/p' "$tmp/h/stats.json")
    read -r rms wid worst noise <<< "$(python3 "$cmp" "$ref" "$tmp/h/surfaces.csv")"
    echo "$s,hrad,$q,$secs,$rms,$wid,$worst,$noise,$el,$li" | tee -a "$out/accuracy.csv"
  done
  for n in $(pt_paths "$s"); do
    "$ptref" "$s" "$n" "$tmp/pt.csv" 11 2> "$tmp/pt.err"
    secs=$(sed -n 's/.* in \([0-9.]*\) s$/\1/p' "$tmp/pt.err")
    # compare.py reads a solution with r,g,b columns: rename the tracer's ref_* columns
    sed '1s/.*/id,area,emitter,r,g,b,se_r,se_g,se_b/' "$tmp/pt.csv" > "$tmp/pt-sol.csv"
    read -r rms wid worst noise <<< "$(python3 "$cmp" "$ref" "$tmp/pt-sol.csv")"
    echo "$s,pathtracer,$n,$secs,$rms,$wid,$worst,$noise,," | tee -a "$out/accuracy.csv"
  done
  if command -v gnuplot > /dev/null; then
    grep "^$s,hrad," "$out/accuracy.csv" | cut -d, -f3,4,5 | tr , ' ' > "$tmp/h.dat"
    grep "^$s,pathtracer," "$out/accuracy.csv" | cut -d, -f3,4,5 | tr , ' ' > "$tmp/p.dat"
    gnuplot <<EOF
set terminal pngcairo size 720,480 font ",11" noenhanced
set output "$out/accuracy-$s.png"
set title "$s: error against a path-traced reference"
set xlabel "seconds (2 cores)"
set ylabel "area-weighted RMS error of polygon means (%)"
set logscale xy
set grid
set key top right
plot "$tmp/h.dat" using 2:3 with linespoints lw 2 pt 7 title "hrad (BF_low = A_e, labelled)", \
     "$tmp/h.dat" using 2:3:1 with labels offset 0,1 notitle, \
     "$tmp/p.dat" using 2:3 with linespoints lw 2 pt 5 title "path tracer (paths per polygon, labelled)", \
     "$tmp/p.dat" using 2:3:1 with labels offset 0,-1 notitle
EOF
  fi
done
echo "accuracy: wrote $out/accuracy.csv and accuracy-*.png" >&2
