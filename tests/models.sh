#!/usr/bin/env bash
# Real third-party models: every OBJ of Debian's assimp-testmodels package (installed by
# scripts/setup.sh; skipped visibly when absent) either solves, with its first material made to
# emit, to a finite, physically bounded result and a complete output set, or fails cleanly: exit
# status 1, one line naming the file, no output directory. Never a crash, a hang (60 s limit), or
# NaN in surfaces.csv.
# The keyhole polygons (KEYHOLES: a hole joined to the outer boundary by an edge traversed both
# ways) must solve, and the area surfaces.csv gives their largest face must equal its area by the
# shoelace formula, computed here (largest_face_area) to 1e-6 relative; a missing one is a SKIP.
# Usage: models.sh HRAD_BINARY SOURCE_DIR SHARED_DIR
set -u
hrad=$1
dir=${HR_MODELS_DIR:-/usr/share/assimp/models}
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
fails=0 passes=0
ok() { passes=$((passes + 1)); echo "ok   $*"; }
bad() { fails=$((fails + 1)); echo "FAIL $*"; }
KEYHOLES="concave_polygon.obj space_in_material_name.obj"
is_keyhole() { case " $KEYHOLES " in *" $1 "*) return 0 ;; esac; return 1; }

# Prints the ordinal (0-based, as surfaces.csv's id) of the face with the most vertices in OBJ
# file $1 and its area: half the length of its Newell vector, the shoelace formula in the face's
# plane, so a hole's loop, wound the other way, counts negative and a bridge's two traversals
# cancel. Independent of hrad's triangulation.
largest_face_area() {
  awk '{ sub(/\r$/, "") }
    $1 == "v" { nv++; X[nv] = $2; Y[nv] = $3; Z[nv] = $4 }
    $1 == "f" {
      nf++
      if (NF - 1 <= best) next
      best = NF - 1; id = nf - 1
      for (i = 2; i <= NF; i++) {
        split($i, r, "/"); k = r[1] + 0; if (k < 0) k += nv + 1
        px[i - 1] = X[k]; py[i - 1] = Y[k]; pz[i - 1] = Z[k]
      }
    }
    END {
      for (i = 1; i <= best; i++) {
        j = i % best + 1
        nx += (py[i] - py[j]) * (pz[i] + pz[j])
        ny += (pz[i] - pz[j]) * (px[i] + px[j])
        nz += (px[i] - px[j]) * (py[i] + py[j])
      }
      printf "%d %.17g\n", id, 0.5 * sqrt(nx * nx + ny * ny + nz * nz)
    }' "$1"
}

# Compares hrad's area of the largest face of keyhole model $1 (output directory $2).
check_keyhole_area() {
  local id want got
  read -r id want < <(largest_face_area "$1")
  got=$(awk -F, -v id="$id" 'NR > 1 && $1 == id { print $2 }' "$2/surfaces.csv")
  if awk -v g="$got" -v w="$want" 'BEGIN { d = g - w; exit !(g != "" && w > 0 &&
                                                           (d < 0 ? -d : d) <= 1e-6 * w) }'; then
    ok "$(basename "$1"): area of face $id $got = shoelace $want"
  else
    bad "$(basename "$1"): area of face $id '$got', shoelace $want"
  fi
}
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
  timeout 240 "$hrad" --quiet --threads 2 --bf-low 1e-2 --emit "$mat=5,5,5" -o "$out" "$f" \
    > /dev/null 2> "$t/err"
  st=$?
  errs=$(grep -v '^hrad: warning' "$t/err")
  if [ "$st" = 0 ]; then
    if [ -s "$out/surfaces.csv" ] && ! grep -qiE 'nan|inf' "$out/surfaces.csv"; then
      ok "$name solves ($(sed -n 's/^ *"elements": \([0-9]*\),/\1/p' "$out/stats.json") elements)"
      if is_keyhole "$name"; then check_keyhole_area "$f" "$out"; fi
    else
      bad "$name: exit 0 but surfaces.csv missing or not finite"
    fi
  elif is_keyhole "$name"; then
    bad "$name: a keyhole polygon must solve, got status $st: $errs"
  elif [ "$st" = 1 ] && [ "$(printf '%s\n' "$errs" | grep -c .)" = 1 ] && [ ! -e "$out" ]; then
    ok "$name fails cleanly: $errs"
  else
    bad "$name: status $st, output dir $([ -e "$out" ] && echo left || echo absent): $errs"
  fi
done < <(find "$dir" -name '*.obj' -size -2M | sort)
for k in $KEYHOLES; do
  [ -n "$(find "$dir" -name "$k")" ] || echo "SKIP $k not found under $dir (no keyhole area check)"
done
echo "models.sh: $passes passed, $fails failed ($n models under $dir)"
[ "$fails" = 0 ]
