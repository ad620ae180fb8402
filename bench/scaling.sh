#!/usr/bin/env bash
# Scaling with the scene's size: hrad on the built-in hall:N (991 N^2 + 70 N triangles: 1061 for
# N = 1, about a million for 32) on 1 and 2 threads; time and memory against the triangles n.
#   bash bench/scaling.sh BUILD_DIR [OUT_DIR]
# Each run is
#   hrad --quiet --no-progress --threads T --size 320x240 --outputs json,png $CLUSTER_OPTS
#        -o DIR hall:N
# Environment:
#   SCALE_SIZES    the N to run (default "1 2 4 8 16 32"; until clustering lands, initial linking
#                  is O(n^2) and --max-pairs refuses N >= 4: a refused run is recorded as such)
#   SCALE_THREADS  thread counts (default "1 2")
#   CLUSTER_OPTS   extra hrad options, e.g. "--cluster on" (default none)
#   SCALE_OUTPUTS  hrad --outputs (default json,png: the solver and one small picture, not the
#                  meshes, which would dominate the time and the disk of a million triangles)
#   SCALE_TIMEOUT  seconds a run may take before it is stopped (default 3600)
#   SCALE_APPEND   1: add to OUT/scaling.csv instead of starting it again (the plot shows all)
# Writes OUT/scaling.csv (one row a run: N, threads, triangles, status, wall seconds, the
# solver's own seconds, peak RSS in MB, elements, links, iterations), each run's stderr as
# OUT/hall-N-tT.err, the picture of each size as OUT/hall-N.png, and OUT/scaling.png: wall time
# and peak RSS against n, log-log, with c n log n and c n^2 guides through the smallest run.
# Peak RSS is /usr/bin/time's %M where it exists, else stats.json's peak_rss_mb.
set -eu
build=$(cd "$1" && pwd)
out=${2:-$build/bench}
mkdir -p "$out"
out=$(cd "$out" && pwd)
hrad=$build/hrad
sizes=${SCALE_SIZES:-1 2 4 8 16 32}
threads=${SCALE_THREADS:-1 2}
outputs=${SCALE_OUTPUTS:-json,png}
limit=${SCALE_TIMEOUT:-3600}
# shellcheck disable=SC2206
extra=(${CLUSTER_OPTS:-})
gnutime=
[ -x /usr/bin/time ] && /usr/bin/time -f %M true 2> /dev/null && gnutime=/usr/bin/time
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The value of a "key": number line of stats.json.
json() { sed -n "s/^ *\"$1\": \\([0-9.e+-]*\\),*\$/\\1/p" "$2" | head -1; }

csv=$out/scaling.csv
# SCALE_APPEND=1 adds rows to an existing scaling.csv (runs spread over calls) and plots them all
if [ "${SCALE_APPEND:-0}" != 1 ] || [ ! -s "$csv" ]; then
  echo "n_cells,threads,triangles,status,wall_s,solve_s,peak_rss_mb,elements,links,iterations" \
    > "$csv"
fi
for n in $sizes; do
  for t in $threads; do
    err=$out/hall-$n-t$t.err
    rm -rf "$tmp/o" "$tmp/time"
    cmd=("$hrad" --quiet --no-progress --threads "$t" --size 320x240 --outputs "$outputs"
         "${extra[@]}" -o "$tmp/o" "hall:$n")
    echo "scaling: hall:$n, $t thread(s): ${cmd[*]}" >&2
    t0=$(date +%s.%N)
    rc=0
    if [ -n "$gnutime" ]; then
      timeout "$limit" "$gnutime" -f %M -o "$tmp/time" "${cmd[@]}" 2> "$err" || rc=$?
    else
      timeout "$limit" "${cmd[@]}" 2> "$err" || rc=$?
    fi
    t1=$(date +%s.%N)
    wall=$(awk -v a="$t0" -v b="$t1" 'BEGIN {printf "%.3f", b - a}')
    tri=$((991 * n * n + 70 * n)) # the count of builtin.c, for runs that end before stats.json
    solve='' rss='' el='' li='' it=''
    if [ "$rc" = 0 ] && [ -s "$tmp/o/stats.json" ]; then
      status=ok
      j=$tmp/o/stats.json
      tri=$(json input_polygons "$j")
      solve=$(sed -n 's/.*"total": \([0-9.e+-]*\)}.*/\1/p' "$j")
      el=$(json elements "$j")
      li=$(json links "$j")
      it=$(json iterations "$j")
      rss=$(json peak_rss_mb "$j")
      [ -f "$out/hall-$n.png" ] || cp "$tmp/o/hall-$n.png" "$out/" 2> /dev/null || true
    elif [ "$rc" = 124 ]; then
      status=timeout
    else
      status="exit $rc"
    fi
    # /usr/bin/time's last line is the peak RSS in KB (it prints a note first when the command
    # was killed by a signal); it also covers runs that fail
    if [ -s "$tmp/time" ]; then
      kb=$(tail -1 "$tmp/time")
      case $kb in
        *[!0-9]* | '') ;;
        *) rss=$(awk -v k="$kb" 'BEGIN {printf "%.1f", k / 1024}') ;;
      esac
    fi
    row="$n,$t,$tri,$status,$wall,$solve,$rss,$el,$li,$it"
    echo "$row" >> "$csv"
    echo "scaling: $row" >&2
    if [ "$status" != ok ]; then
      echo "scaling: hall:$n on $t thread(s): $status: $(grep -m1 '^hrad:' "$err" || true)" >&2
    fi
  done
done

pic=
if command -v gnuplot > /dev/null; then
  # the smallest successful 1-thread run anchors the guides (else the smallest of any)
  read -r n0 w0 m0 <<< "$(awk -F, '$4 == "ok" && $2 == 1 {print $3, $5, $7; exit}' "$csv")"
  [ -n "${n0:-}" ] ||
    read -r n0 w0 m0 <<< "$(awk -F, 'NR > 1 && $4 == "ok" {print $3, $5, $7; exit}' "$csv")"
  # every thread count in the file
  threads=$(awk -F, 'NR > 1 && $4 == "ok" {print $2}' "$csv" | sort -un | tr '\n' ' ')
  if [ -n "${n0:-}" ]; then
    for t in $threads; do
      awk -F, -v t="$t" '$4 == "ok" && $2 == t {print $3, $5, $7}' "$csv" > "$tmp/t$t.dat"
    done
    plots_time='' plots_mem=''
    for t in $threads; do
      [ -s "$tmp/t$t.dat" ] || continue
      style="with linespoints lw 2 pt 7 title \"$t thread(s)\""
      plots_time="$plots_time \"$tmp/t$t.dat\" using 1:2 $style,"
      plots_mem="$plots_mem \"$tmp/t$t.dat\" using 1:3 $style,"
    done
    gnuplot << EOF
set terminal pngcairo size 1100,480 font ",11" noenhanced
set output "$out/scaling.png"
set logscale xy
set grid
set key top left
set xlabel "triangles n (hall:N)"
nlogn(x, x0, y0) = y0 * x * log(x) / (x0 * log(x0))
n2(x, x0, y0) = y0 * (x / x0) ** 2
set multiplot layout 1,2 title "hrad on hall:N $(echo "${CLUSTER_OPTS:-}" | tr -d '"')"
set title "wall time"
set ylabel "seconds"
plot $plots_time \
     nlogn(x, $n0, $w0) with lines dt 2 lc rgb "gray40" title "c n log n", \
     n2(x, $n0, $w0) with lines dt 3 lc rgb "gray70" title "c n^2"
set title "peak memory"
set ylabel "peak RSS (MB)"
plot $plots_mem \
     nlogn(x, $n0, $m0) with lines dt 2 lc rgb "gray40" title "c n log n", \
     n2(x, $n0, $m0) with lines dt 3 lc rgb "gray70" title "c n^2"
unset multiplot
EOF
    pic=" and $out/scaling.png"
  else
    echo "scaling: no successful run, no picture" >&2
  fi
fi
echo "scaling: wrote $csv$pic" >&2
