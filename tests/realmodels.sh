#!/usr/bin/env bash
# Real models through assimp (src/import.c), from Debian's assimp-testmodels: each is solved with
# a material made to emit, and its output .glb must keep the input's object (node) and material
# names, pass the Khronos glTF-Validator, and hold finite radiosities whose per-object means
# (tests/glb_objects.mjs, area-weighted over the _RADIOSITY attribute) meet expectations that
# follow from the materials alone: in a channel where a material reflects nothing, its
# surfaces' radiosity is exactly their emission (B = E + rho H with rho = 0), so an emitter shows
# E and a non-emitter 0 there; in a channel that reflects, an emitter facing lit surfaces shows
# more than E, and at most E / (1 - rho).
# Skipped (exit 77, ctest SKIP_RETURN_CODE) without the models, node or the validator.
# Usage: realmodels.sh HRAD_BINARY SOURCE_DIR [SHARED_DIR]
set -u
hrad=$1 src=$2
dir=${HR_MODELS_DIR:-/usr/share/assimp/models}
for need in "$dir/glTF/TwoBoxes/TwoBoxes.gltf" "$dir/FBX/cubes_with_names.fbx" \
  "$dir/3DS/test1.3ds" "$src/node_modules/gltf-validator"; do
  [ -e "$need" ] || { echo "SKIP: $need missing (scripts/setup.sh installs it)"; exit 77; }
done
command -v node >/dev/null || { echo "SKIP: node missing"; exit 77; }
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
fails=0 passes=0
ok() { passes=$((passes + 1)); echo "ok   $*"; }
bad() { fails=$((fails + 1)); echo "FAIL $*"; }

# solve NAME MODEL EMIT...: solves into $t/NAME (glb and png only) and writes $t/NAME.txt
solve() {
  local name=$1 model=$2
  shift 2
  if "$hrad" --quiet --threads 2 --size 160x120 --outputs glb,png -o "$t/$name" "$@" "$model" \
    2> "$t/$name.err"; then
    ok "$name: solved"
  else
    bad "$name: hrad failed: $(cat "$t/$name.err")"
    return 1
  fi
  local glb
  glb=$(ls "$t/$name"/*.glb)
  node "$src/tests/validate_glb.mjs" "$glb" > "$t/$name.val" 2>&1 && ok "$name: validator clean" \
    || { bad "$name: validator"; cat "$t/$name.val"; }
  node "$src/tests/glb_objects.mjs" "$glb" > "$t/$name.txt" 2>&1 || bad "$name: glb_objects failed"
  grep -q '^max nan' "$t/$name.txt" && bad "$name: radiosity not finite"
  return 0
}

# expect NAME 'KIND "LABEL"' AWK-CONDITION DESCRIPTION: the line of node/material LABEL exists and
# satisfies the condition on its fields (a = area, r, g, b = mean radiosity)
expect() {
  local name=$1 key=$2 cond=$3 what=$4 line
  line=$(grep -F "$key " "$t/$name.txt" | head -1)
  if [ -z "$line" ]; then
    bad "$name: no $key in the output glb"
    return
  fi
  if echo "${line#"$key "}" | awk "{ a = \$1; r = \$2; g = \$3; b = \$4; exit !($cond) }"; then
    ok "$name: $key: $what ($line)"
  else
    bad "$name: $key: want $what, got: $line"
  fi
}

# glTF 1.0: two boxes (objects BottomBox, TopBox) of one material Effect-Red (rho 0.8, 0, 0),
# all emitting 1: green and blue are exactly 1; red exceeds 1 where the boxes see each other,
# more for the small box, whose bottom face sees the big box's top at close range.
if solve twoboxes "$dir/glTF/TwoBoxes/TwoBoxes.gltf" --emit Effect-Red=1,1,1; then
  expect twoboxes 'node "BottomBox"' 'g > 0.99999 && g < 1.00001 && b > 0.99999 && b < 1.00001 &&
    r > 1.01 && r < 1.2' "G = B = 1, 1.01 < R < 1.2"
  expect twoboxes 'node "TopBox"' 'g > 0.99999 && g < 1.00001 && r > 1.1 && r < 5' \
    "G = 1, 1.1 < R < 5 (1/(1-0.8))"
  expect twoboxes 'material "Effect-Red"' 'a > 7.4999 && a < 7.5001' "area 6 + 1.5"
fi

# FBX with a Cyrillic object name: Cube2 (Mat_Green, rho 0, 0.8, 0) is lit by Cube3 and Куб1
# (Mat_Red, rho 0.8, 0, 0) emitting 5.
if solve fbx "$dir/FBX/cubes_with_names.fbx" --emit Mat_Red=5,5,5; then
  expect fbx 'node "Cube2"' 'r == 0 && b == 0 && g > 0.01 && g < 5' "R = B = 0, lit in G"
  expect fbx 'node "Cube3"' 'g > 4.9999 && g < 5.0001 && b > 4.9999 && b < 5.0001 &&
    r >= 5 && r <= 25' "G = B = 5, 5 <= R <= 25"
  expect fbx 'material "Mat_Red"' 'g > 4.9999 && g < 5.0001 && r >= 5 && r <= 25' \
    "the emitters (Cube3, part of Куб1): G = 5, 5 <= R <= 25"
  grep -q '^node "Куб1"' "$t/fbx.txt" && ok "fbx: node Куб1 (UTF-8 name kept)" || bad "fbx: no Куб1"
  expect fbx 'material "Mat_Green"' 'a > 1199.99 && a < 1200.01' "Cube2 and the green part"
fi

# 3DS with JPEG textures named in upper case (IMAGE1.JPG for IMAGE1.jpg): nine wall boxes
# Box01..Box10 and three materials; the textured polygons' reflectance variants stay one
# material each in the output. Pillars of '3 - Default' emit 5.
if solve tds "$dir/3DS/test1.3ds" --emit '3 - Default=5,5,5'; then
  n=$(grep -c '^node "Box' "$t/tds.txt")
  [ "$n" = 9 ] && ok "tds: 9 Box nodes" || bad "tds: $n Box nodes, want 9"
  m=$(grep -c '^material ' "$t/tds.txt")
  [ "$m" = 3 ] && ok "tds: 3 materials (texture variants merged)" || bad "tds: $m materials"
  expect tds 'material "3 - Default"' 'r >= 5 && g >= 5 && b >= 5 && r < 10' "emitters: 5 <= B"
  expect tds 'material "1 - Default"' 'r > 0 && r < 1' "lit, far below the lamps"
  w=$("$hrad" --list-materials "$dir/3DS/test1.3ds" 2>&1 >/dev/null)
  [ -z "$w" ] && ok "tds: every texture read" || bad "tds: warnings: $w"
fi

# --list-materials on a PLY (no materials of its own: the grey 'default') and a glTF.
[ "$("$hrad" --list-materials "$dir/PLY/cube.ply" 2>&1)" = default ] && ok "ply: 'default'" \
  || bad "ply --list-materials: $("$hrad" --list-materials "$dir/PLY/cube.ply" 2>&1)"
lm=$("$hrad" --list-materials "$dir/glTF/CesiumMilkTruck/CesiumMilkTruck.gltf" 2>&1 | tr '\n' ,)
[ "$lm" = "Effect-wheels,Effect-truck,Effect-glass,Effect-window_trim," ] \
  && ok "truck --list-materials" || bad "truck --list-materials: $lm"

echo "realmodels: $passes passed, $fails failed"
[ "$fails" -eq 0 ]
