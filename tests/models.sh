#!/usr/bin/env bash
# Real third-party models: every OBJ of Debian's assimp-testmodels package (installed by
# scripts/setup.sh; skipped visibly when absent) either solves, with its first material made to
# emit, to a finite, physically bounded result and a complete output set, or fails cleanly: exit
# status 1, one line naming the file, no output directory. Never a crash, a hang (60 s limit), or
# NaN in surfaces.csv.
# Usage: models.sh HRAD_BINARY SOURCE_DIR SHARED_DIR
set -u
hrad=$1
dir=${HR_MODELS_DIR:-/usr/share/assimp/models}
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
fails=0 passes=0
ok() { passes=$((passes + 1)); echo "ok   $*"; }
bad() { fails=$((fails + 1)); echo "FAIL $*"; }
if [ ! -d "$dir" ]; then
  echo "SKIP $dir not found (Debian package assimp-testmodels; scripts/setup.sh installs it)"
  exit 0
fi
n=0
while IFS= read -r f; do
  n=$((n + 1))
  name=$(basename "$f")
  # The first material the file uses (the loader calls faces before any usemtl "default").
  mat=$(sed -n 's/^usemtl[ \t]\{1,\}\(.*[^ \t\r]\)[ \t\r]*$/\1/p' "$f" | head -n 1)
  [ -n "$mat" ] || mat=default
  out="$t/o$n"
  timeout 60 "$hrad" --quiet --threads 2 --bf-low 1e-2 --emit "$mat=5,5,5" -o "$out" "$f" \
    > /dev/null 2> "$t/err"
  st=$?
  errs=$(grep -v '^hrad: warning' "$t/err")
  if [ "$st" = 0 ]; then
    if [ -s "$out/surfaces.csv" ] && ! grep -qiE 'nan|inf' "$out/surfaces.csv"; then
      ok "$name solves ($(sed -n 's/^ *"elements": \([0-9]*\),/\1/p' "$out/stats.json") elements)"
    else
      bad "$name: exit 0 but surfaces.csv missing or not finite"
    fi
  elif [ "$st" = 1 ] && [ "$(printf '%s\n' "$errs" | grep -c .)" = 1 ] && [ ! -e "$out" ]; then
    ok "$name fails cleanly: $errs"
  else
    bad "$name: status $st, output dir $([ -e "$out" ] && echo left || echo absent): $errs"
  fi
done < <(find "$dir" -name '*.obj' -size -2M | sort)
echo "models.sh: $passes passed, $fails failed ($n models under $dir)"
[ "$fails" = 0 ]
