#!/usr/bin/env bash
# run.sh: builds and runs the libFuzzer targets (TESTING.md; `make fuzz`, `make fuzz-merge`).
#   run.sh run   BUILD SECONDS [TARGET...]  build with clang -DHR_FUZZ=ON in BUILD, then fuzz each
#                                           TARGET (default: obj objmtl) for SECONDS, one after
#                                           the other
#   run.sh merge BUILD [TARGET...]          add the inputs of BUILD/corpus_TARGET that reach new
#                                           edges to tests/fuzz/corpus_TARGET (-merge=1
#                                           -use_counters=0: edges, not hit counts, so that the
#                                           corpora stay at a few hundred small files)
# Each target fuzzes BUILD/corpus_TARGET, a working copy seeded from tests/fuzz/corpus_TARGET and
# tests/fuzz/crashes/TARGET, with the dictionary obj.dict; a crash or failed invariant is saved
# as BUILD/crashes/TARGET/crash-* (also leak-*, timeout-*, oom-*), and the script exits 1 after
# all targets ran. To keep a crash as a regression test, fix it and copy the file into
# tests/fuzz/crashes/TARGET/ (the ctest fuzz_replay_TARGET runs it from then on).
# Installs clang, its runtime libraries and libomp with apt-get when libFuzzer is missing.
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
mode=${1:-run}
build=${2:-build-fuzz}
shift 2 || shift $#
if [ "$mode" = run ]; then
  secs=${1:-60}
  shift || true
fi
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(obj objmtl)
cc=${CLANG:-clang}
jobs=$(nproc)

have_libfuzzer() {
  command -v "$cc" >/dev/null 2>&1 &&
    printf '#include <stddef.h>\n#include <stdint.h>\nint LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) { (void)d; (void)n; return 0; }\n' |
      "$cc" -fsanitize=fuzzer,address,undefined -fopenmp -x c - -o /dev/null 2>/dev/null
}
if ! have_libfuzzer; then
  echo "fuzz: installing clang, libclang-rt-dev, libomp-dev" >&2
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends clang \
    libclang-rt-dev libomp-dev >/dev/null
  have_libfuzzer || { echo "fuzz: $cc cannot build with -fsanitize=fuzzer" >&2; exit 1; }
fi

cd "$here"
cmake -S . -B "$build" -DCMAKE_C_COMPILER="$cc" -DHR_FUZZ=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$build" -j "$jobs" --target $(printf 'fuzz_%s ' "${targets[@]}")

status=0
for t in "${targets[@]}"; do
  bin="$build/tests/fuzz/fuzz_$t"
  work="$build/corpus_$t"
  if [ "$mode" = merge ]; then
    [ -d "$work" ] || { echo "fuzz: no $work (run make fuzz first)" >&2; exit 1; }
    before=$(ls tests/fuzz/corpus_$t | wc -l)
    "$bin" -merge=1 -use_counters=0 -max_len=8192 -timeout=10 "tests/fuzz/corpus_$t" "$work" \
      2>"$build/merge_$t.log" ||
      { tail -20 "$build/merge_$t.log" >&2; exit 1; }
    echo "fuzz_$t: corpus $before -> $(ls tests/fuzz/corpus_$t | wc -l) files"
    continue
  fi
  mkdir -p "$work" "$build/crashes/$t"
  cp -n tests/fuzz/corpus_$t/* "$work"/ 2>/dev/null || true
  find tests/fuzz/crashes/$t -maxdepth 1 -type f ! -name '.*' -exec cp -n {} "$work"/ \;
  echo "fuzz_$t: ${secs}s on $work ($(ls "$work" | wc -l) inputs)"
  if "$bin" -dict=tests/fuzz/obj.dict -max_len=8192 -timeout=10 -rss_limit_mb=2048 \
      -max_total_time="$secs" -print_final_stats=1 -artifact_prefix="$build/crashes/$t/" \
      "$work" >"$build/fuzz_$t.log" 2>&1; then
    grep -E '^stat::(number_of_executed_units|average_exec_per_sec|new_units_added)' \
      "$build/fuzz_$t.log" | sed "s/^/  /"
  else
    status=1
    echo "fuzz_$t: FAILED, see $build/fuzz_$t.log; inputs in $build/crashes/$t/:" >&2
    ls "$build/crashes/$t" >&2
    grep -E 'fuzz check failed|ERROR: |runtime error' "$build/fuzz_$t.log" | head -5 >&2 || true
  fi
done
exit $status
