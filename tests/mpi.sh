#!/usr/bin/env bash
# The distributed solver under mpirun (README "Many processes"): the same answer, bit for bit, as
# one process, for P = 1, 2, 3, 4, 7 ranks, 1 or 2 threads per rank and random assignments of
# the elements (subtrees at every depth) to ranks (surfaces.csv, the images, the meshes and the
# counts of stats.json), with graph balancing by each method, and with clustering (--cluster on:
# cluster links on their receivers' owners, any P, threads, assignment, migration, balancing,
# checkpoints); a rank that fails in any phase (HRAD_TEST_FAIL) ends the whole run with one line,
# exit status 1, no outputs and no hang; bad input reported once; a bad option refused once.
# Runs above 2 ranks are oversubscribed on 2 cores: correctness only, no timing here.
# Usage: mpi.sh HRAD_BINARY SOURCE_DIR SHARED_DIR
set -u
hrad=$1
if ! command -v mpirun >/dev/null; then
  echo "SKIP: mpirun not found (scripts/setup.sh installs openmpi-bin)"
  exit 0
fi
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
# surfaces.csv with every bit of each number (hexadecimal floats), so that "identical" means
# bit-identical solutions, not equal to 9 digits (a summation order that differs only in the
# last bits is caught: a clustered gather in another order passes at 9 digits)
export HRAD_TEST_EXACT=1
# Under the sanitizer build (make test-asan): Open MPI leaves its own allocations at
# MPI_Finalize, some in plugins already unloaded (no module to suppress by), so leak checking is
# off for these runs only; every other test checks hrad's leaks, and ASan still checks memory
# errors here.
export ASAN_OPTIONS="${ASAN_OPTIONS:-}${ASAN_OPTIONS:+:}detect_leaks=0"
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
fails=0 passes=0
ok() { passes=$((passes + 1)); echo "ok   $*"; }
bad() { fails=$((fails + 1)); echo "FAIL $*"; }
mpi() { local np=$1; shift; timeout 120 mpirun -np "$np" --bind-to none "$hrad" "$@"; }
# same DIR1 DIR2 SCENE WHAT: outputs and counts identical
same() {
  local a=$1 b=$2 sc=$3 what=$4 f d=""
  for f in surfaces.csv "$sc.png" "$sc-elements.png" "$sc.ply" "$sc.glb"; do
    cmp -s "$a/$f" "$b/$f" || d="$d $f"
  done
  local ca cb
  local keys='"(elements|elements_all|links|initial_links|iterations|rays|converged|cluster_links)"'
  ca=$(grep -E "$keys" "$a/stats.json")
  cb=$(grep -E "$keys" "$b/stats.json")
  [ "$ca" = "$cb" ] || d="$d stats.json-counts"
  [ -z "$d" ] && ok "$what: identical to one process" || bad "$what: differs in$d"
}

# ---------------------------------------------------------------- same answer, any P
q=(--quiet --size 96x72 --bf-low 3e-3)
"$hrad" "${q[@]}" --threads 2 -o "$t/c1" cornell || bad "plain cornell run failed"
for np in 1 2 3 4 7; do
  mpi "$np" "${q[@]}" --threads 1 -o "$t/c$np-mpi" cornell && same "$t/c1" "$t/c$np-mpi" cornell \
    "cornell, $np ranks x 1 thread" || bad "cornell on $np ranks: exit $?"
done
mpi 2 "${q[@]}" --threads 2 -o "$t/c2t2" cornell && same "$t/c1" "$t/c2t2" cornell \
  "cornell, 2 ranks x 2 threads" || bad "cornell 2x2: exit $?"
mpi 3 "${q[@]}" --threads 1 --balance area -o "$t/c3a" cornell && same "$t/c1" "$t/c3a" cornell \
  "cornell, 3 ranks, --balance area (whole surfaces)" || bad "cornell --balance area: exit $?"
# room at these settings is cut along contact lines (--cut-contacts, default on): every rank
# cuts the scene it loads alike, so the pieces, their ids and the answer are the same
"$hrad" "${q[@]}" --threads 1 -o "$t/r1" room 2> /dev/null || bad "plain room run failed"
for np in 2 3; do
  mpi "$np" "${q[@]}" --threads 1 -o "$t/r$np-mpi" room && same "$t/r1" "$t/r$np-mpi" room \
    "room (cut along contact lines), $np ranks" || bad "room on $np ranks: exit $?"
done
# stats.json says how a run was spread: ranks, and the balancing (null in one process)
sj() { grep -c -e "\"ranks\": $2," -e "\"balance\": $3" "$1/stats.json"; }
[ "$(sj "$t/c1" 1 null)" = 2 ] \
  && [ "$(sj "$t/c3-mpi" 3 '{"method": "anneal", "balancings": [1-9]')" = 2 ] \
  && [ "$(sj "$t/c3a" 3 '{"method": "area", "balancings": 0,')" = 2 ] \
  && ok "stats.json: ranks and balancing (1 process; 3 ranks, annealing by default; area)" \
  || bad "stats.json: ranks or balance wrong: $(grep -h -e ranks -e '"balance"' "$t/c1/stats.json" \
    "$t/c3-mpi/stats.json" "$t/c3a/stats.json" | tr '\n' ' ')"

# ---------------------------------------------------------------- random assignments
# --balance random:N sends every element, at any depth, to a random rank: trees spread over all
# ranks, links split across ranks. MPI_STRESS=50 runs 50 assignments instead of 10.
f=(--quiet --size 64x48 --bf-low 1e-2)
"$hrad" "${f[@]}" --threads 1 -o "$t/fref" floor || bad "plain floor run failed"
for seed in $(seq "${MPI_STRESS:-10}"); do
  np=$((3 + seed % 5))
  mpi "$np" "${f[@]}" --threads 1 --balance "random:$seed" -o "$t/f$seed" floor \
    && same "$t/fref" "$t/f$seed" floor "floor, $np ranks, random assignment $seed" \
    || bad "floor on $np ranks (random:$seed): exit $?"
  rm -rf "$t/f$seed"
done

# ---------------------------------------------------------------- graph balancing
# --balance anneal|metis|orb (paper 2.2.5) moves subtrees after initial linking and, with
# --balance-idle 0 (whatever it costs), every third iteration: the answer does not change.
# ORB on 4 ranks: from the start by bisection of the surfaces, on 3 its partitions after the
# first did not lower Z, so nothing moved again. Annealing also on 17: beyond 16 ranks it joins
# neighbouring surfaces into pieces (hr_partition_tree_cut_near) and shortens its chains.
for mp in anneal:3 metis:3 orb:4 anneal:17; do
  m=${mp%:*} np=${mp#*:}
  mpi "$np" --size 96x72 --bf-low 3e-3 --threads 1 --balance "$m" --balance-idle 0 \
    -o "$t/bal-$m" cornell 2> "$t/bal-$m.err" > /dev/null \
    && same "$t/c1" "$t/bal-$m" cornell \
      "cornell, $np ranks, --balance $m, rebalanced every 3 iterations" \
    || bad "cornell --balance $m on $np ranks: exit $?"
  nb=$(sed -n 's/^graph balancing: \([0-9]*\) times, \([0-9]*\) of them moved.*/\1 \2/p' \
    "$t/bal-$m.err")
  [ "${nb#* }" -ge 2 ] 2>/dev/null && ok "--balance $m, $np ranks: $nb (balancings, migrations)" \
    || bad "--balance $m, $np ranks: fewer than 2 migrations: '${nb:-}'"
  rm -rf "$t/bal-$m"
done

# ---------------------------------------------------------------- elements are distributed
# Each element is owned by exactly one rank (the own counts add up to the one-process element
# count), no rank owns them all, and every rank holds ghosts (copies of others' elements).
mpi 4 --size 64x48 --bf-low 1e-2 --threads 1 -o "$t/fd" floor 2> "$t/ranks" >/dev/null
total=$(grep -o '"elements_all": [0-9]*' "$t/fref/stats.json" | grep -o '[0-9]*$')
if awk -v total="$total" '
    /^rank  elements/ { on = 1; next }
    on && /^element\+link/ { on = 0 }
    on && NF == 7 { n++; own += $2; if ($2 <= 0 || $2 >= total || $3 <= 0) bad = 1 }
    END { exit !(n == 4 && own == total && !bad) }' "$t/ranks"; then
  ok "elements distributed: 4 ranks own $total elements between them, each holds ghosts"
else
  bad "elements distributed (one-process count $total)"
  cat "$t/ranks"
fi

# ---------------------------------------------------------------- migration
# HRAD_TEST_MIGRATE=SEED: after every iteration every element moves to a new random rank with
# the links it receives (hr_solver_migrate, what graph balancing will use): same answer.
HRAD_TEST_MIGRATE=7 mpi 3 "${q[@]}" --threads 1 -o "$t/mg" cornell \
  && same "$t/c1" "$t/mg" cornell "3 ranks, every element migrated after every iteration" \
  || bad "migration run: exit $?"

# ---------------------------------------------------------------- a rank fails
for spec in 1:init 2:refine:3 1:push-pull:2 0:refine:2; do
  start=$(date +%s)
  HRAD_TEST_FAIL=$spec mpi 3 "${q[@]}" --threads 1 -o "$t/x" cornell 2> "$t/err"
  rc=$? secs=$(($(date +%s) - start))
  n=$(grep -c '^hrad:' "$t/err")
  if [ $rc -ne 0 ] && [ $rc -ne 124 ] && [ "$n" = 1 ] && grep -q "^hrad: rank ${spec%%:*}: .*injected by HRAD_TEST_FAIL" "$t/err" \
     && [ ! -e "$t/x" ]; then
    ok "rank failure $spec: exit $rc, one line, no outputs (${secs}s)"
  else
    bad "rank failure $spec: exit $rc, $n hrad lines, outputs $(ls "$t/x" 2>/dev/null | wc -l)"
    cat "$t/err"
  fi
done

# ---------------------------------------------------------------- clustering
# --cluster on (docs/design.md, "Clustering"): each cluster link lives on its receiver's owner
# and carries its place in the one-process order, in which the gather sums; the clusters'
# fields are summed over the ranks. The same answer for any P, threads, random assignment,
# migration after every iteration and balancing; a clustered checkpoint resumes on other P; a
# rank failing within cluster refinement (or building the clusters) ends the run cleanly.
k=(--quiet --size 96x72 --bf-low 3e-3 --cluster on)
"$hrad" "${k[@]}" --threads 2 -o "$t/k1" cornell || bad "plain clustered cornell run failed"
grep -q '"cluster_links": [1-9]' "$t/k1/stats.json" \
  || bad "cornell --cluster on made no cluster links"
for np in 2 3; do # (4: the resumed checkpoint below)
  mpi "$np" "${k[@]}" --threads 1 -o "$t/k$np-mpi" cornell && same "$t/k1" "$t/k$np-mpi" cornell \
    "clustered cornell, $np ranks x 1 thread" || bad "clustered cornell on $np ranks: exit $?"
done
mpi 2 "${k[@]}" --threads 2 -o "$t/k2t2" cornell && same "$t/k1" "$t/k2t2" cornell \
  "clustered cornell, 2 ranks x 2 threads" || bad "clustered cornell 2x2: exit $?"
HRAD_TEST_MIGRATE=5 mpi 3 "${k[@]}" --threads 1 -o "$t/kmg" cornell \
  && same "$t/k1" "$t/kmg" cornell "clustered cornell, 3 ranks, elements migrated every iteration" \
  || bad "clustered migration run: exit $?"
# balancing owns the clusters' links too (from compact pieces of the hierarchy: every method
# moves some of them)
for m in anneal metis orb; do
  mpi 3 "${k[@]:1}" --threads 1 --balance $m --balance-idle 0 -o "$t/kbal" cornell \
    2> "$t/kbal.err" > /dev/null \
    && same "$t/k1" "$t/kbal" cornell "clustered cornell, 3 ranks, --balance $m" \
    || bad "clustered cornell --balance $m: exit $?"
  nb=$(sed -n 's/^graph balancing: .* moved elements, \([0-9]*\) clusters.*/\1/p' "$t/kbal.err")
  [ "${nb:-0}" -ge 1 ] && ok "clustered cornell --balance $m: $nb clusters' links moved" \
    || bad "clustered cornell --balance $m: no cluster moved: $(grep balancing "$t/kbal.err")"
done
# hall:1 (1,061 triangles, fine sources): migration leaves a rank's links unsorted, and the
# oracle's bound for sorted links must then decide as its exact test does (its sources'
# children's variation was missing from it: the bound kept links that split after migration)
h=(--quiet --size 64x48 --max-iters 6)
"$hrad" "${h[@]}" --threads 1 -o "$t/h1" hall:1 || bad "plain hall:1 run failed"
HRAD_TEST_MIGRATE=5 mpi 2 "${h[@]}" --threads 1 -o "$t/h2" hall:1 \
  && same "$t/h1" "$t/h2" hall-1 "hall:1, 2 ranks, elements migrated every iteration" \
  || bad "hall:1 migration run: exit $?"
# floor: 292 surfaces, 291 clusters, cluster links received by elements at every depth
kf=(--quiet --size 64x48 --bf-low 1e-2 --cluster on)
"$hrad" "${kf[@]}" --threads 1 -o "$t/kfref" floor || bad "plain clustered floor run failed"
for seed in 3 4; do
  np=$((2 + seed))
  mpi "$np" "${kf[@]}" --threads 1 --balance "random:$seed" -o "$t/kf$seed" floor \
    && same "$t/kfref" "$t/kf$seed" floor "clustered floor, $np ranks, random assignment $seed" \
    || bad "clustered floor on $np ranks (random:$seed): exit $?"
done
# --bf-first: the clustered linking before the first gather at its own BF_e (on floor it
# changes 81 of 161 k links)
"$hrad" "${kf[@]}" --threads 1 --bf-first 1e-3 -o "$t/kff1" floor \
  || bad "plain clustered floor --bf-first run failed"
[ "$(grep '"links"' "$t/kfref/stats.json")" != "$(grep '"links"' "$t/kff1/stats.json")" ] \
  || bad "clustered floor: --bf-first 1e-3 changed no link"
mpi 3 "${kf[@]}" --threads 1 --bf-first 1e-3 -o "$t/kff3" floor \
  && same "$t/kff1" "$t/kff3" floor "clustered floor, --bf-first 1e-3, 3 ranks" \
  || bad "clustered floor --bf-first on 3 ranks: exit $?"
mpi 3 "${k[@]}" --threads 1 --max-iters 6 --checkpoint "$t/kk3.ckpt" -o "$t/kk3" cornell
mpi 2 "${k[@]}" --threads 1 --resume "$t/kk3.ckpt" -o "$t/kk3r2" cornell \
  && same "$t/k1" "$t/kk3r2" cornell "clustered checkpoint of 3 ranks, resumed on 2" \
  || bad "clustered resume on 2 ranks: exit $?"
"$hrad" "${k[@]}" --resume "$t/kk3.ckpt" -o "$t/kk3r1" cornell \
  && same "$t/k1" "$t/kk3r1" cornell "clustered checkpoint of 3 ranks, resumed in one process" \
  || bad "clustered resume in one process: exit $?"
"$hrad" "${k[@]}" --max-iters 5 --checkpoint "$t/kk1.ckpt" -o "$t/kk1" cornell
mpi 4 "${k[@]}" --threads 1 --resume "$t/kk1.ckpt" -o "$t/kk1r4" cornell \
  && same "$t/k1" "$t/kk1r4" cornell "clustered checkpoint of 1 process, resumed on 4 ranks" \
  || bad "clustered resume on 4 ranks: exit $?"
for spec in 1:init 2:cluster:1 0:cluster:4; do
  HRAD_TEST_FAIL=$spec mpi 3 "${k[@]}" --threads 1 -o "$t/kx" cornell 2> "$t/err"
  rc=$? n=$(grep -c '^hrad:' "$t/err")
  if [ $rc -ne 0 ] && [ $rc -ne 124 ] && [ "$n" = 1 ] && [ ! -e "$t/kx" ] \
     && grep -q "^hrad: rank ${spec%%:*}: .*clusters\? .*injected by HRAD_TEST_FAIL" "$t/err"; then
    ok "clustered, rank failure $spec: exit $rc, one line, no outputs"
  else
    bad "clustered, rank failure $spec: exit $rc, $n hrad lines, outputs $(ls "$t/kx" 2>&1)"
    cat "$t/err"
  fi
done
rm -rf "$t"/k*

# ---------------------------------------------------------------- bad input and usage
printf 'v 0 0 0\nv 1 0 0\nf 1 2 9\n' > "$t/bad.obj"
mpi 3 --quiet -o "$t/y" "$t/bad.obj" 2> "$t/err"
rc=$?
[ $rc -ne 0 ] && [ "$(grep -c '^hrad:' "$t/err")" = 1 ] && grep -q "bad.obj:3: vertex index 9 out of range" "$t/err" \
  && [ ! -e "$t/y" ] && ok "bad input on 3 ranks: one line, exit $rc" \
  || { bad "bad input on 3 ranks: exit $rc"; cat "$t/err"; }

# ---------------------------------------------------------------- checkpoints across P
# Written by P ranks, resumed on any other P (and on one process), the result is bit-identical;
# also after a kill -9 of the whole job at a random moment.
mpi 3 "${q[@]}" --threads 1 --max-iters 6 --checkpoint "$t/k3.ckpt" -o "$t/k3" cornell
for np in 1 2; do
  if [ "$np" = 1 ]; then "$hrad" "${q[@]}" --resume "$t/k3.ckpt" -o "$t/k3r$np" cornell
  else mpi "$np" "${q[@]}" --threads 1 --resume "$t/k3.ckpt" -o "$t/k3r$np" cornell; fi
  same "$t/c1" "$t/k3r$np" cornell "checkpoint of 3 ranks after iteration 6, resumed on $np"
done
"$hrad" "${q[@]}" --max-iters 5 --checkpoint "$t/k1.ckpt" -o "$t/k1" cornell
mpi 4 "${q[@]}" --threads 1 --resume "$t/k1.ckpt" -o "$t/k1r4" cornell \
  && same "$t/c1" "$t/k1r4" cornell "checkpoint of 1 process after iteration 5, resumed on 4 ranks" \
  || bad "resume on 4 ranks: exit $?"
( exec mpirun -np 3 --bind-to none "$hrad" --size 96x72 --bf-low 3e-3 --threads 1 \
    --checkpoint "$t/kk.ckpt" --checkpoint-every 0 -o "$t/kk" cornell > /dev/null 2>&1 ) &
pid=$!
# (up to 60 s for the first checkpoint: a loaded machine starts 3 ranks slowly)
for _ in $(seq 6000); do [ -e "$t/kk.ckpt" ] && break; sleep 0.01; done
[ -e "$t/kk.ckpt" ] || bad "the 3-rank job wrote no checkpoint within 60 s"
sleep "0.$((RANDOM % 5))"
kill -KILL $pid 2>/dev/null
wait $pid 2>/dev/null
pkill -KILL -f "$hrad --size 96x72 --bf-low 3e-3 --threads 1 --checkpoint $t/kk.ckpt" 2>/dev/null
mpi 2 --size 96x72 --bf-low 3e-3 --threads 1 --resume "$t/kk.ckpt" -o "$t/kkr" cornell 2> "$t/err" >/dev/null
it=$(grep -o 'after iteration [0-9]*' "$t/err")
same "$t/c1" "$t/kkr" cornell "3-rank job killed (kill -9), resumed on 2 ranks $it"
# The balancing graph's work weights (balance.c): W = links received (element and cluster links)
# + 1 + 8 x the rays refinement cast for the element's links per iteration, the rays counted on
# whichever rank refined the link and merged on rank 0: the same on 2 ranks (random owners: every
# tree spread) as on one process, clustered or not, and the rays part is not zero.
for cl in off on; do
  "$hrad" --quiet --threads 1 --cluster $cl --outputs csv,json --dump-graph "$t/g1.graph" \
    -o "$t/g1" cornell \
    && mpi 2 --quiet --threads 1 --cluster $cl --outputs csv,json --dump-graph "$t/g2.graph" \
      -o "$t/g2" cornell \
    && L=$(sed -n 's/^ *"links": \([0-9]*\),$/\1/p' "$t/g1/stats.json") \
    && awk -v L="$L" 'FNR == 1 { f++ } /^edges/ { e[f] = 1 }
      !e[f] && NF == 6 { n[f]++; w[f, n[f]] = $3; id[f, n[f]] = $1 }
      END { if (n[1] != n[2] || n[1] < 100) exit 1
        for (i = 1; i <= n[1]; i++) {
          if (id[1, i] != id[2, i]) exit 1
          d = w[1, i] - w[2, i]; if (d < 0) d = -d; if (d > 1e-9 * w[1, i]) exit 1
          sw += w[1, i] }
        printf "%d nodes, %d links, W sum %.0f", n[1], L, sw
        exit !(L > 0 && sw > 1.05 * (n[1] + L)) }' "$t/g1.graph" "$t/g2.graph" > "$t/gw" \
    && ok "balancing weights (--cluster $cl) with refinement's rays, the same on 2 ranks as on" \
      "one: $(cat "$t/gw")" \
    || bad "balancing weights (--cluster $cl) differ between 1 process and 2 ranks, or carry no" \
      "rays: $(cat "$t/gw" 2>/dev/null)"
  rm -rf "$t/g1" "$t/g2" "$t/g1.graph" "$t/g2.graph"
done
mpi 2 --quiet --balance nonsense -o "$t/y" cornell 2> "$t/err"
[ "$(grep -c "^hrad: --balance must be" "$t/err")" = 1 ] && ok "--balance nonsense: one usage line" \
  || { bad "--balance nonsense"; cat "$t/err"; }

echo "$passes passed, $fails failed"
[ $fails -eq 0 ]
