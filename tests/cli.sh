#!/usr/bin/env bash
# The command line end to end: outputs of a real run, golden counts, identical results for any
# thread count, snapshots, glTF validation of a real result, and bad input (one-line message
# naming file and line, exit status 1, usage errors 2, no output files).
# Usage: cli.sh HRAD_BINARY SOURCE_DIR SHARED_DIR
set -u
hrad=$1 src=$2 shared=$3
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
fails=0 passes=0
ok() { passes=$((passes + 1)); echo "ok   $*"; }
bad() { fails=$((fails + 1)); echo "FAIL $*"; }
json() { sed -n "s/^ *\"$2\": \([^,]*\),\{0,1\}$/\1/p" "$1"; }

# ---------------------------------------------------------------- a real run: cornell
if "$hrad" --quiet -o "$t/c" cornell; then
  for f in surfaces.csv stats.json cornell.png cornell-elements.png cornell.ply cornell.glb viewer.html; do
    [ -s "$t/c/$f" ] && ok "cornell wrote $f" || bad "cornell did not write $f"
  done
  [ "$(head -1 "$t/c/surfaces.csv")" = "id,area,r,g,b,status" ] && ok "surfaces.csv header" || bad "surfaces.csv header"
  rows=$(($(wc -l < "$t/c/surfaces.csv") - 1))
  [ "$rows" = "$(json "$t/c/stats.json" input_polygons)" ] && ok "one csv row per input polygon ($rows)" \
    || bad "csv rows $rows != surfaces"
  for k in surfaces elements links iterations rays; do
    v=$(json "$t/c/stats.json" "$k")
    [ -n "$v" ] && [ "$v" -gt 0 ] 2>/dev/null && ok "stats.json $k = $v" || bad "stats.json $k missing"
  done
  for k in init_graph refine push_pull total; do
    grep -q "\"$k\": [0-9]" "$t/c/stats.json" && ok "stats.json time_s.$k" || bad "stats.json time_s.$k"
  done
  ls -a "$t/c" | grep -q '^\.hrad-tmp' && bad "temporary directory left behind" || ok "no temporary directory left"
  if [ -d "$src/node_modules/gltf-validator" ]; then
    node "$src/tests/validate_glb.mjs" "$t/c/cornell.glb" > "$t/val.txt" 2>&1 && ok "cornell.glb passes glTF-Validator" \
      || { bad "cornell.glb fails glTF-Validator"; cat "$t/val.txt"; }
  else
    bad "gltf-validator not installed (scripts/setup.sh installs it)"
  fi
else
  bad "hrad cornell failed"
fi

# ---------------------------------------------------------------- golden counts for room
# Fixed options; a change here means the algorithm changed: update deliberately.
opts="--bf-low 3e-3 --area-min 1e-3 --rays 16 --seed 1 --bf-start 0.05 --bf-factor 4"
if "$hrad" --quiet $opts -o "$t/r1" --threads 1 room; then
  el=$(json "$t/r1/stats.json" elements); li=$(json "$t/r1/stats.json" links)
  it=$(json "$t/r1/stats.json" iterations)
  echo "     room: elements $el links $li iterations $it"
  [ "$el" = "${GOLD_ELEMENTS:-1872}" ] && ok "room elements golden ($el)" || bad "room elements $el (golden ${GOLD_ELEMENTS:-1872})"
  [ "$li" = "${GOLD_LINKS:-308511}" ] && ok "room links golden ($li)" || bad "room links $li (golden ${GOLD_LINKS:-308511})"
  [ "$it" = "${GOLD_ITERS:-37}" ] && ok "room iterations golden ($it)" || bad "room iterations $it (golden ${GOLD_ITERS:-37})"
  for n in 2 3 4; do
    "$hrad" --quiet $opts -o "$t/r$n" --threads $n room
    cmp -s "$t/r1/surfaces.csv" "$t/r$n/surfaces.csv" && ok "room surfaces.csv identical with $n threads" \
      || bad "room surfaces.csv differs with $n threads"
  done
  # A different jitter seed changes the sampled visibility, not the answer: every polygon within
  # 5% of the brightest non-emitting polygon's radiosity, total power within 2%.
  "$hrad" --quiet $opts -o "$t/rs" --seed 2 room
  read -r dmax pw <<< "$(paste -d, "$t/r1/surfaces.csv" "$t/rs/surfaces.csv" | awk -F, '
    NR > 1 && $3 < 50 { for (c = 3; c <= 5; c++) { if ($c > mx) mx = $c; d = $c - $(c + 6); if (d < 0) d = -d; if (d > m) m = d } }
    NR > 1 { p1 += $2 * ($3 + $4 + $5); p2 += $8 * ($9 + $10 + $11) }
    END { dp = (p1 - p2) / p2; if (dp < 0) dp = -dp; printf "%.4f %.4f\n", m / mx, dp }')"
  awk -v d="$dmax" -v p="$pw" 'BEGIN { exit !(d < 0.05 && p < 0.02) }' \
    && ok "seed 2 vs seed 1: polygons within $dmax of the brightest, total power within $pw" \
    || bad "seed 2 vs seed 1 differ: polygons by $dmax of the brightest, total power by $pw"
else
  bad "hrad room failed"
fi

# ---------------------------------------------------------------- snapshots
if "$hrad" --quiet --snapshots --size 160x120 -o "$t/s" cornell; then
  n=$(ls "$t/s"/iter-*.png 2>/dev/null | wc -l)
  it=$(json "$t/s/stats.json" iterations)
  [ "$n" = "$it" ] && ok "one snapshot per iteration ($n)" || bad "$n snapshots for $it iterations"
  last=$(ls "$t/s"/iter-*.png | sort | tail -1)
  cmp -s "$last" "$t/s/cornell.png" && ok "final image equals the last snapshot" || bad "final image differs from last snapshot"
else
  bad "hrad --snapshots failed"
fi

# ---------------------------------------------------------------- --verify, --verify-image
if "$hrad" --quiet -o "$t/v" --size 64x48 --verify 2000 --verify-image 4 cornell 2> "$t/verr.txt"; then
  [ "$(head -1 "$t/v/verify.csv")" = "id,area,material,emitter,hrad_r,hrad_g,hrad_b,ref_r,ref_g,ref_b,se_r,se_g,se_b,rel_err" ] \
    && ok "verify.csv header" || bad "verify.csv header: $(head -1 "$t/v/verify.csv")"
  [ $(($(wc -l < "$t/v/verify.csv") - 1)) = "$(json "$t/v/stats.json" surfaces)" ] \
    && ok "verify.csv: one row per solved polygon" || bad "verify.csv rows"
  grep -q "^verify: area-weighted RMS error" "$t/verr.txt" && ok "verify summary: $(grep '^verify: area' "$t/verr.txt")" \
    || bad "no verify summary: $(cat "$t/verr.txt")"
  grep -q "^verify-image: mean relative per-pixel error" "$t/verr.txt" && [ -s "$t/v/cornell-reference.png" ] \
    && ok "verify-image wrote cornell-reference.png and its error line" || bad "verify-image: $(cat "$t/verr.txt")"
else
  bad "hrad --verify failed: $(cat "$t/verr.txt")"
fi

# ---------------------------------------------------------------- bad input
# expect STATUS PATTERN ARGS...: exit status, stderr is one line matching PATTERN, no output dir.
expect() {
  local want=$1 pat=$2; shift 2
  local out="$t/bad-out"
  rm -rf "$out"
  "$hrad" -o "$out" "$@" 2> "$t/err.txt" > /dev/null
  local st=$? lines
  lines=$(grep -vc '^hrad: warning' "$t/err.txt")
  if [ "$st" = "$want" ] && grep -qE -e "$pat" "$t/err.txt" && [ ! -e "$out" ] && { [ "$want" = 2 ] || [ "$lines" = 1 ]; }; then
    ok "exit $want: $(grep -v '^hrad: warning' "$t/err.txt" | head -1)"
  else
    bad "args '$*': status $st (want $want), dir exists: $([ -e "$out" ] && echo yes || echo no), stderr: $(cat "$t/err.txt")"
  fi
}
mk() { printf "$2" > "$t/$1"; }
mk light.mtl 'newmtl light\nKd 0 0 0\nKe 5 5 5\nnewmtl white\nKd 0.5 0.5 0.5\n'
base='mtllib light.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nv 0 1 0\nv 1 1 0\nv 1 1 1\nv 0 1 1\nusemtl white\nf 1 4 3 2\nusemtl light\nf 5 6 7 8\n'
mk good.obj "$base"
mk badidx.obj "${base}f 1 2 99\n"
mk nan.obj "${base}v nan 0 0\n"
mk two.obj "${base}f 1 2\n"
mk nomtl.obj 'mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n'
mk dark.obj 'mtllib light.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl white\nf 1 2 3\n'
mk degen.obj "${base}v 2 0 0\nf 1 2 9\n"
expect 1 "^hrad: $t/missing.obj: cannot open" "$t/missing.obj"
expect 1 "^hrad: $t/badidx.obj:14: " "$t/badidx.obj"
expect 1 "^hrad: $t/nan.obj:14: " "$t/nan.obj"
expect 1 "^hrad: $t/two.obj:14: " "$t/two.obj"
expect 1 "^hrad: .*no emitting surface" "$t/dark.obj"
expect 1 "^hrad: .*no emitting surface" "$t/nomtl.obj"
expect 1 "^hrad: unknown scene 'nosuch'" nosuch
expect 2 "unknown option '--frobnicate'" --frobnicate room
expect 2 "--rays: not a number" --rays many room
expect 1 "rays must be in" --rays 0 room
expect 2 "--verify: expected a whole number" --verify 0 room
expect 2 "--verify-image: expected a whole number" --verify-image 2.5 room
expect 1 "no material named 'nosuch'" --emit nosuch=1,1,1 room
# Degenerate polygons are skipped with a warning naming the line; the run succeeds.
if "$hrad" -o "$t/degen-out" "$t/degen.obj" 2> "$t/err.txt" >/dev/null && grep -q "degen.obj:15: degenerate" "$t/err.txt"; then
  ok "degenerate polygon skipped with a warning naming its line"
else
  bad "degenerate polygon: $(cat "$t/err.txt")"
fi
# A missing MTL is a warning (grey default), documented in obj.c.
"$hrad" -o "$t/nomtl-out" "$t/nomtl.obj" 2> "$t/err.txt" >/dev/null
grep -q "cannot open material library" "$t/err.txt" && ok "missing MTL warns" || bad "missing MTL: $(cat "$t/err.txt")"
# Output directory that is a file: error, nothing written.
touch "$t/afile"
"$hrad" --quiet -o "$t/afile" "$t/good.obj" 2> "$t/err.txt"
[ $? = 1 ] && grep -q "not a directory" "$t/err.txt" && ok "output path is a file: clean error" || bad "output path is a file: $(cat "$t/err.txt")"
# --help and usage
"$hrad" --help | grep -q "Usage: hrad" && ok "--help" || bad "--help"

# ---------------------------------------------------------------- third-party scenes
cb="$shared/scenes/cornell/CornellBox-Original.obj"
if [ -f "$cb" ]; then
  "$hrad" --quiet -o "$t/cb" "$cb" && [ -s "$t/cb/CornellBox-Original.png" ] && ok "CornellBox-Original.obj solves unmodified" \
    || bad "CornellBox-Original.obj failed"
else
  echo "SKIP $cb not found (../shared is absent)"
fi
conf="$shared/scenes/conference/conference.obj"
if [ -f "$conf" ]; then
  # Too large for O(n^2) initial linking: a clear refusal, quickly, naming the numbers.
  "$hrad" -o "$t/conf" --emit "Material #0=5,5,5" "$conf" 2> "$t/err.txt" >/dev/null
  st=$?
  [ "$st" = 1 ] && grep -q "surface pairs" "$t/err.txt" && [ ! -e "$t/conf" ] && ok "conference refused: $(tail -1 "$t/err.txt")" \
    || bad "conference: status $st: $(cat "$t/err.txt")"
else
  echo "SKIP $conf not found (../shared is absent)"
fi

echo "$passes passed, $fails failed"
[ "$fails" = 0 ]
