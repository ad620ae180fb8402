#!/usr/bin/env bash
# The distributed solver's tables (BENCHMARKS.md, "Distributed solver"): for each scene and
# P = 1, 2, 4, 8 ranks of 1 thread, the paper's phase table (init graph, refine, push-pull, sum)
# and hrad's per-rank table (links, leaves, rays, busy and MPI seconds, collectives, bytes sent,
# RSS; min/mean/max). Runs above the machine's cores are oversubscribed: their wall times are not
# speed-ups (the table says so); their counts, volumes and imbalance are what predicts scaling.
# Then the model of bench/mpimodel.c for each scene, and the balancing methods of
# bench/partbench.c on the scene's final patch/link graph (P = 2 to 64).
# Usage: bench/mpi.sh BUILD [SCENE...]   (default scenes: room floor museum)
set -u
build=${1:-build}
shift || true
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(room floor museum)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
cores=$(nproc)
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "machine: $(nproc) cores, $(date -u '+%Y-%m-%d %H:%M UTC'), $(git -C "$(dirname "$0")/.." rev-parse --short HEAD)"
for sc in "${scenes[@]}"; do
  for np in 1 2 4 8; do
    note=""
    [ "$np" -gt "$cores" ] && note=" (oversubscribed: $np ranks on $cores cores)"
    echo "== $sc, $np ranks x 1 thread$note"
    mpirun -np "$np" --bind-to none "$build/hrad" --threads 1 --size 64x48 -o "$out/o" "$sc" 2>&1 \
      | sed -n '/^threads init graph/,$p' | grep -v '^hrad: wrote'
  done
  echo "== model: $build/bench/mpimodel $sc"
  "$build/bench/mpimodel" "$sc"
  echo "== balancing methods on the final graph: $build/bench/partbench (graph of a 2-rank run)"
  mpirun -np 2 --bind-to none "$build/hrad" --quiet --threads 1 --size 64x48 \
    --dump-graph "$out/$sc.graph" -o "$out/g" "$sc" && "$build/bench/partbench" "$out/$sc.graph"
done
