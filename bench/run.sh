#!/usr/bin/env bash
# bench/run.sh BUILD_DIR: the benchmark behind `make bench` (see BENCHMARKS.md).
#
#   1. hrad on room, floor and museum with --threads 1..nproc (default solver options): the
#      paper's phase table (Bohn & Garmann, section 2.3, tables 1 and 2) plus sizes, rates,
#      speedup and memory, with the paper's own figures beside ours.
#   2. Ray rates: the solver's rays / (init_graph + refine) beside Embree's raw rtcOccluded16
#      rate on the same scene (bench/rayrate.c), in the same run.
#   3. Speedup curve: $BENCH_OUT/speedup.png (gnuplot), skipped with a message without gnuplot.
#   4. callgrind instruction counts per phase of `hrad --threads 1 room` (skipped without
#      valgrind).
#   5. The distributed solver and graph balancing (bench/mpi.sh; BENCH_MPI=0 skips it).
# Results: $BENCH_OUT (default BUILD_DIR/bench): runs.csv (every run), summary.csv (the tables),
# rayrate.csv, callgrind.csv, speedup.dat, speedup.png, callgrind.out.
#
# Environment: BENCH_OUT, BENCH_SCENES (default "room floor museum"), BENCH_REPS (runs per
# timing, default 3; the minimum is reported), BENCH_MUSEUM_REPS (default 3), BENCH_SLOW_S
# (default 20: a configuration whose first run takes longer is run only once, to keep `make
# bench` within a few minutes; the museum takes 10-40 s a run), BENCH_THREADS (default "1 2 ... nproc"), BENCH_PASSIVE=0 to skip the extra runs with
# OMP_WAIT_POLICY=passive at more than 1 thread (on a machine shared with other work, OpenMP
# threads that spin at barriers while a sibling is descheduled can make N threads slower than
# one; the passive rows show how much of that is spinning), BENCH_CALLGRIND=0 to skip part 4.
set -euo pipefail

die() {
  echo "bench/run.sh: error: $*" >&2
  exit 1
}

[[ $# -le 1 ]] || die "usage: bash bench/run.sh [BUILD_DIR]"
BUILD_ARG=${1:-build}
[[ -d $BUILD_ARG ]] || die "build directory '$BUILD_ARG' not found; build first: make build" \
  "(or cmake -S . -B $BUILD_ARG -DCMAKE_BUILD_TYPE=Release && cmake --build $BUILD_ARG)"
BUILD=$(cd "$BUILD_ARG" && pwd)
HRAD=$BUILD/hrad
RAYRATE=$BUILD/bench/rayrate
[[ -x $HRAD ]] || die "$HRAD is missing or not executable; build first: make build"
[[ -x $RAYRATE ]] || die "$RAYRATE is missing; rebuild so that bench/CMakeLists.txt is" \
  "configured: cmake -S . -B $BUILD_ARG && cmake --build $BUILD_ARG"
if grep -q '^CMAKE_BUILD_TYPE:STRING=' "$BUILD/CMakeCache.txt" 2>/dev/null; then
  btype=$(sed -n 's/^CMAKE_BUILD_TYPE:STRING=//p' "$BUILD/CMakeCache.txt")
  [[ $btype == Release ]] || echo "bench/run.sh: warning: $BUILD is a '$btype' build," \
    "timings are not representative (use -DCMAKE_BUILD_TYPE=Release)" >&2
fi

NPROC=$(nproc)
BENCH_OUT=${BENCH_OUT:-$BUILD/bench}
SCENES=${BENCH_SCENES:-room floor museum}
REPS=${BENCH_REPS:-3}
MUSEUM_REPS=${BENCH_MUSEUM_REPS:-3}
SLOW_S=${BENCH_SLOW_S:-20}
THREADS=${BENCH_THREADS:-$(seq -s ' ' 1 "$NPROC")}
[[ $REPS =~ ^[1-9][0-9]*$ && $MUSEUM_REPS =~ ^[1-9][0-9]*$ ]] ||
  die "BENCH_REPS and BENCH_MUSEUM_REPS must be positive integers"
mkdir -p "$BENCH_OUT" || die "cannot create $BENCH_OUT"
BENCH_OUT=$(cd "$BENCH_OUT" && pwd)
TMP=$(mktemp -d "${TMPDIR:-/tmp}/hrad-bench.XXXXXX")
trap 'rm -rf "$TMP"' EXIT

# Value of a numeric field of stats.json ("key": value); keys are unique in the file.
jnum() {
  local v
  v=$(grep -o "\"$2\": *[-0-9.eE+]*" "$1" | head -n 1 | sed 's/.*: *//')
  [[ -n $v ]] || die "field '$2' missing in $1"
  printf '%s' "$v"
}

# CPU actually available: NPROC busy loops of fixed work at once; (user + sys) / real = the
# number of cores they got (NPROC on an idle machine, less when other work is running).
probe_cores() {
  local TIMEFORMAT='%R %U %S' t
  t=$({ time {
    for ((i = 0; i < NPROC; i++)); do awk 'BEGIN { for (i = 0; i < 1e7; i++) s += i }' & done
    wait
  }; } 2>&1)
  awk -v n="$NPROC" '{ printf "%.2f of %d cores", ($2 + $3) / $1, n }' <<<"$t"
}

cpu_model=$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -n 1)
mem_gib=$(awk '/^MemTotal:/ {printf "%.1f", $2 / 1048576}' /proc/meminfo)
echo "== hrad benchmark: $(date '+%Y-%m-%d %H:%M %Z'), $(hostname)"
echo "   $NPROC cores ($cpu_model), $mem_gib GiB; load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "   CPU available to an $NPROC-thread job (busy-loop probe): $(probe_cores) before the runs"
echo "   binary $HRAD; results in $BENCH_OUT"
echo "   minimum of $REPS runs per timing (museum: $MUSEUM_REPS; one run where the first takes over"
echo "   $SLOW_S s; museum with OMP_WAIT_POLICY=passive: one run); times are wall-clock seconds"
echo

# ---------------------------------------------------------------- 1. solver runs
RUNS=$BENCH_OUT/runs.csv
echo "scene,threads,omp_wait,rep,surfaces,elements,links,rays,init_graph,refine,gather,push_pull,total,peak_rss_mb,process_wall" >"$RUNS"
for scene in $SCENES; do
  reps=$REPS
  [[ $scene == museum ]] && reps=$MUSEUM_REPS
  for t in $THREADS; do
    waits=default
    [[ $t -gt 1 && ${BENCH_PASSIVE:-1} != 0 ]] && waits="default passive"
    for w in $waits; do
      n=$reps
      [[ $scene == museum && $w == passive ]] && n=1
      for ((r = 1; r <= n; r++)); do
        out=$TMP/out-$scene-$t-$r
        t0=$(date +%s.%N)
        if [[ $w == passive ]]; then
          env OMP_WAIT_POLICY=passive "$HRAD" --threads "$t" --quiet -o "$out" "$scene" \
            >"$TMP/log" 2>&1 || { cat "$TMP/log" >&2; die "hrad --threads $t $scene failed"; }
        else
          "$HRAD" --threads "$t" --quiet -o "$out" "$scene" >"$TMP/log" 2>&1 ||
            { cat "$TMP/log" >&2; die "hrad --threads $t $scene failed"; }
        fi
        wall=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.4f", b - a }')
        st=$out/stats.json
        [[ -f $st ]] || die "hrad wrote no $st"
        row="$scene,$t,$w,$r"
        for k in surfaces elements links rays init_graph refine gather push_pull total peak_rss_mb; do
          row+=",$(jnum "$st" "$k")"
        done
        echo "$row,$wall" >>"$RUNS"
        printf '   %-7s threads %2d %-7s run %d/%d: solve %8.3f s, process %8.3f s\n' "$scene" \
          "$t" "$w" "$r" "$n" "$(jnum "$st" total)" "$wall" >&2
        rm -rf "$out"
        if ((r == 1 && n > 1)) && awk -v x="$wall" -v l="$SLOW_S" 'BEGIN { exit !(x > l) }'; then
          echo "   $scene --threads $t ($w): first run took over $SLOW_S s, running it once" >&2
          n=1
        fi
      done
    done
  done
done
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
probe_after=$(probe_cores)

# Per (scene, threads): the minimum of every time column over the runs. refine = refine + gather
# (the paper's refine column includes do_link); sum = init + refine + gather + push-pull of the
# same run. Mrays/s = rays / (init_graph + refine): the phases that cast rays, including all
# their non-ray work (form factors, shafts, refinement decisions).
SUMMARY=$BENCH_OUT/summary.csv
awk -F, -v OFS=, '
NR == 1 { next }
{
  k = $1 "," $2 "," $3
  if (!(k in n)) { order[++nk] = k; el[k] = $6; ln[k] = $7; ry[k] = $8; sf[k] = $5; rss[k] = $14 }
  n[k]++
  if ($6 != el[k] || $7 != ln[k] || $8 != ry[k]) var[k] = 1
  ig = $9; rf = $10 + $11; pp = $12; sm = $9 + $10 + $11 + $12; vt = $9 + $10
  if (n[k] == 1 || ig < mig[k]) mig[k] = ig
  if (n[k] == 1 || rf < mrf[k]) mrf[k] = rf
  if (n[k] == 1 || pp < mpp[k]) mpp[k] = pp
  if (n[k] == 1 || sm < msm[k]) msm[k] = sm
  if (n[k] == 1 || vt < mvt[k]) mvt[k] = vt
  if (n[k] == 1 || $13 < mtot[k]) mtot[k] = $13
  if (n[k] == 1 || $15 < mwall[k]) mwall[k] = $15
  if ($14 > rss[k]) rss[k] = $14
}
END {
  print "scene,threads,omp_wait,runs,surfaces,init_graph_s,refine_s,push_pull_s,sum_s,total_s,elements,links,rays,links_per_s,mrays_per_s,speedup,peak_rss_mb,mb_per_mlinks,varies,process_wall_s"
  for (i = 1; i <= nk; i++) {
    k = order[i]; split(k, a, ",")
    if (a[2] == 1 && a[3] == "default") base[a[1]] = msm[k]
    sp = (a[1] in base) ? base[a[1]] / msm[k] : ""
    print k, n[k], sf[k], mig[k], mrf[k], mpp[k], msm[k], mtot[k], el[k], ln[k], ry[k], \
      ln[k] / mtot[k], ry[k] / mvt[k] / 1e6, sp, rss[k], rss[k] / (ln[k] / 1e6), var[k] + 0, mwall[k]
  }
}' "$RUNS" >"$SUMMARY"

paper() {
  case $1 in
  room)
    cat <<'EOF'
   paper, table 1 ("room", 27 polygons, 3300 elements, 23200 links), seconds on the 1995 MIMD
   machine, columns init graph / refine / push-pull / sim. ann. / sum:
      1 proc: 6 / 354 / 14 / 0 / 374      2: 4 / 404 / 13 / 0 / 421     4: 2 / 362 / 11 / 12 / 377
      8:      2 / 209 /  9 / 17 / 238     16: 2 / 130 / 5 / 14 / 151    32: 3 / 85 / 4 / 22 / 114
      64:     6 /  74 /  4 / 60 / 144     (speedup of the sum: 1.6 on 16, 3.3 on 32, 2.6 on 64)
EOF
    ;;
  floor)
    cat <<'EOF'
   paper, table 2 ("floor", 289 polygons, 6380 elements, 56400 links), seconds, columns
   init graph / refine / push-pull / sim. ann. / sum:
      1 proc: 1134 / 1278 / 61 / 0 / 2473    2: 644 / 1567 / 36 / 0 / 2247   4: 349 / 1145 / 22 / 20 / 1536
      8:       189 /  508 / 11 / 25 / 733   16: 110 /  392 /  9 / 25 / 536   32:  68 /  271 /  7 / 32 / 378
      64:       53 /  170 /  6 / 67 / 296   (speedup of the sum: 1.1 on 2, 8.4 on 64)
EOF
    ;;
  museum)
    cat <<'EOF'
   paper, section 3 (figures 8-11, about 4000 polygons): about 30000 elements and 939000 links,
   about 104 min (6240 s) on 64 processors; no per-phase table.
EOF
    ;;
  esac
}

print_table() { # scene
  awk -F, -v scene="$1" '
  NR == 1 { next }
  $1 == scene {
    if (!hdr) {
      printf "== %s (%d surfaces)\n", scene, $5
      printf "   %-9s %10s %10s %10s %10s %8s %9s %11s %10s %8s %7s %7s %9s %8s\n", "threads", \
        "init graph", "refine", "push-pull", "sum", "elements", "links", "rays", "links/s", \
        "Mrays/s", "speedup", "RSS MB", "MB/Mlink", "process"
      hdr = 1
    }
    printf "   %-9s %10.4f %10.4f %10.4f %10.4f %8d %9d %11d %10.0f %8.2f %7.2f %7.1f %9.1f %8.3f%s\n", \
      $2 ($3 == "passive" ? " passive" : ""), $6, $7, $8, $9, $11, $12, $13, $14, $15, $16, \
      $17, $18, $20, ($19 ? "  (sizes differ between runs!)" : "")
    if ($2 == 1) { e1 = $11; l1 = $12 } else if ($11 != e1 || $12 != l1) \
      printf "   note: %d threads gave other element/link counts than 1 thread\n", $2
  }' "$SUMMARY"
}

for scene in $SCENES; do
  print_table "$scene"
  paper "$scene"
  awk -F, -v scene="$scene" '
    BEGIN { p["room"] = 374; p["floor"] = 2473; pl["room"] = 23200; pl["floor"] = 56400
            pl["museum"] = 939000; pe["room"] = 3300; pe["floor"] = 6380; pe["museum"] = 30000 }
    NR > 1 && $1 == scene && $2 == 1 && $3 == "default" {
      printf "   ours vs paper: %.2fx the elements, %.2fx the links", $11 / pe[scene], $12 / pl[scene]
      if (scene in p) printf "; 1 thread %.4g s vs 1 processor %d s (%.0fx faster)", $9, p[scene], p[scene] / $9
      else printf "; 1 thread %.4g s vs 6240 s on 64 processors", $9
      printf "\n"
    }' "$SUMMARY"
  echo
done
echo "   columns: minimum over the runs of each time (s); refine = refine + gather (do_link);"
echo "   sum = init graph + refine + push-pull; links/s = links / total; Mrays/s = rays /"
echo "   (init graph + refine without gather); speedup = sum(1 thread) / sum; RSS = peak RSS;"
echo "   process = wall time of the whole hrad process (scene build, solve, writing all outputs);"
echo "   'passive': the same with OMP_WAIT_POLICY=passive (threads sleep instead of spinning)."
echo "   load average after the runs: $load_after; CPU available (probe): $probe_after"
echo

# ---------------------------------------------------------------- 2. ray rates
echo "== ray rates, one thread: Embree raw packets vs the solver (bench/rayrate.c)"
RR=$BENCH_OUT/rayrate.csv
# shellcheck disable=SC2086 # SCENES is a word list
"$RAYRATE" --links 50000 --reps 5 --csv "$RR" $SCENES || die "rayrate failed"
echo
printf '   %-7s %14s %16s %16s %14s %14s\n' scene "solver Mrays/s" "raw16 all Mr/s" \
  "raw16 vis Mr/s" "hr_vis all" "raw16/solver"
for scene in $SCENES; do
  solver=$(awk -F, -v s="$scene" 'NR > 1 && $1 == s && $2 == 1 && $3 == "default" {print $15}' "$SUMMARY")
  rawa=$(awk -F, -v s="$scene" '$1 == s && $2 == "all" && $3 == "embree-raw16" {print $7}' "$RR")
  rawv=$(awk -F, -v s="$scene" '$1 == s && $2 == "visible" && $3 == "embree-raw16" {print $7}' "$RR")
  hvis=$(awk -F, -v s="$scene" '$1 == s && $2 == "all" && $3 == "hr_vis" {print $7}' "$RR")
  [[ -n $solver ]] || continue
  awk -v s="$scene" -v a="$solver" -v b="${rawa:-0}" -v c="${rawv:-0}" -v d="${hvis:-0}" 'BEGIN {
    printf "   %-7s %14.2f %16.2f %16.2f %14.2f %7.1f-%.1fx\n", s, a, b, c, d, \
      (c < b ? c : b) / a, (c < b ? b : c) / a }'
done
echo "   solver Mrays/s = rays / (init graph + refine) of the 1-thread run: every second of the"
echo "   ray-casting phases counted as ray time (form factors, shafts, refinement decisions too),"
echo "   so it is a lower bound on the solver's own ray rate (an upper bound on its time per ray)."
echo "   raw16: rtcOccluded16, one 16-ray packet per link, no filter; hr_vis: hr_vis_segments."
echo "   rayrate columns here are thread CPU time (best of 5), robust to a busy machine; the"
echo "   solver column is wall-clock (best of the runs). 'all' = random facing surface pairs,"
echo "   'vis' = those with a visible segment. raw16/solver: the range over 'all' and 'vis'."
echo

# ---------------------------------------------------------------- 3. speedup plot
DAT=$BENCH_OUT/speedup.dat
{
  printf '# threads'
  for scene in $SCENES; do printf ' %s %s-passive' "$scene" "$scene"; done
  echo
  for t in $THREADS; do
    printf '%s' "$t"
    for scene in $SCENES; do
      for w in default passive; do
        v=$(awk -F, -v s="$scene" -v t="$t" -v w="$w" \
          'NR > 1 && $1 == s && $2 == t && ($3 == w || t == 1) {print $16; exit}' "$SUMMARY")
        printf ' %s' "${v:-NaN}"
      done
    done
    echo
  done
} >"$DAT"
if command -v gnuplot >/dev/null 2>&1; then
  maxt=$(echo "$THREADS" | tr ' ' '\n' | sort -n | tail -n 1)
  plot="x title 'ideal' with lines dashtype 2 linecolor rgb 'gray40'"
  col=2
  lc=1
  for scene in $SCENES; do
    plot+=", '$DAT' using 1:$col title '$scene' with linespoints linewidth 2 pointsize 1.5 linecolor $lc"
    if [[ ${BENCH_PASSIVE:-1} != 0 ]]; then
      plot+=", '$DAT' using 1:$((col + 1)) title '$scene, OMP_WAIT_POLICY=passive' with linespoints dashtype 3 linewidth 2 pointsize 1.2 linecolor $lc"
    fi
    col=$((col + 2))
    lc=$((lc + 1))
  done
  term="pngcairo size 800,560 font 'sans,11'"
  if ! gnuplot -e "set terminal pngcairo" >/dev/null 2>&1; then term="png size 800,560"; fi
  gnuplot <<EOF || echo "   (gnuplot failed; speedup.png not written)"
set terminal $term
set termoption noenhanced
set output '$BENCH_OUT/speedup.png'
set title "hrad speedup (sum of phases, best of runs), $(date +%Y-%m-%d), $NPROC cores\\nload average $load_after, CPU free: $probe_after"
set xlabel 'threads'
set ylabel 'speedup vs 1 thread'
set xrange [0.8:$maxt + 0.2]
set yrange [0:$maxt + 0.5]
set xtics 1
set key top left
set grid
plot $plot
EOF
  [[ -f $BENCH_OUT/speedup.png ]] && echo "== speedup curve: $BENCH_OUT/speedup.png"
else
  echo "== gnuplot not found: speedup.png skipped (data in $DAT)"
fi
echo

# ---------------------------------------------------------------- 4. callgrind
CG=$BENCH_OUT/callgrind.csv
if [[ ${BENCH_CALLGRIND:-1} == 0 ]]; then
  echo "== callgrind skipped (BENCH_CALLGRIND=0)"
elif ! command -v valgrind >/dev/null 2>&1 || ! command -v callgrind_annotate >/dev/null 2>&1; then
  echo "== callgrind skipped: valgrind (with callgrind_annotate) is not installed"
else
  echo "== callgrind: instructions (inclusive Ir) of hrad --threads 1 --quiet room"
  cgout=$BENCH_OUT/callgrind.out
  if ! valgrind --tool=callgrind --callgrind-out-file="$cgout" "$HRAD" --threads 1 --quiet \
    -o "$TMP/cg" room >"$TMP/cg.log" 2>&1; then
    tail -n 20 "$TMP/cg.log" >&2
    echo "   callgrind run failed (valgrind dies with SIGILL on AVX-512 code: no -march=native)"
  else
    callgrind_annotate --inclusive=yes --threshold=100 "$cgout" >"$TMP/cg.txt"
    # Ir of a function: its exact name, else the sum of its OpenMP bodies (name._omp_fn.N; the
    # static gather and push_pull_all are inlined into hr_solver_run, their bodies are not).
    ir() {
      awk -v f="$1" '
        { name = $0; sub(/^[^:]*:/, "", name); sub(/ \[.*$/, "", name); v = $1; gsub(/,/, "", v) }
        name == f { exact = v }
        index(name, f "._omp_fn.") == 1 { omp += v }
        END { print (exact != "" ? exact : omp + 0) }' "$TMP/cg.txt"
    }
    total=$(awk '/PROGRAM TOTALS/ {v = $1; gsub(/,/, "", v); print v}' "$TMP/cg.txt")
    solve=$(ir hr_solver_run)
    init=$(($(ir hr_vis_create) + $(ir hr_shaft_index_create) + $(ir hr_link_init)))
    refine=$(($(ir hr_link_refine) + $(ir hr_link_sort)))
    gather=$(ir gather)
    pp=$(ir hr_push_pull)
    {
      echo "phase,functions,ir"
      echo "init graph,hr_vis_create+hr_shaft_index_create+hr_link_init,$init"
      echo "refine,hr_link_refine+hr_link_sort,$refine"
      echo "gather,gather,$gather"
      echo "push-pull,hr_push_pull,$pp"
      echo "solve,hr_solver_run,$solve"
      echo "program,PROGRAM TOTALS (incl. scene build and writing the outputs),$total"
      for f in hr_shaft_filter hr_vf_pair hr_ff_pair hr_vis_segments_cand hr_vis_segments write_pictures; do
        echo "  (detail),$f,$(ir "$f")"
      done
    } >"$CG"
    awk -F, -v solve="$solve" 'NR > 1 {
      printf "   %-12s %13.0f Ir  %6.2f%% of solve   %s\n", $1, $3, \
        100 * $3 / solve, $2 }' "$CG"
    echo "   (deterministic: compare these counts across commits; profile in $cgout)"
  fi
fi
# 5. The distributed solver (BENCHMARKS.md, "Distributed solver" and "Graph balancing"): phase
#    and per-rank tables at 1, 2, 4 and 8 ranks, the model, and the balancing methods on the
#    final graphs (bench/mpi.sh). BENCH_MPI=0 skips it; skipped without mpirun.
if [[ ${BENCH_MPI:-1} != 0 ]]; then
  if command -v mpirun >/dev/null; then
    echo
    echo "== 5. distributed solver (bench/mpi.sh)"
    bash "$(dirname "$0")/mpi.sh" "$BUILD" $BENCH_SCENES
  else
    echo "== 5. distributed solver: skipped (no mpirun; scripts/setup.sh installs openmpi-bin)"
  fi
fi
echo
echo "== results: $RUNS $SUMMARY $RR $DAT ${CG}"
echo "   load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
