#!/usr/bin/env bash
# Advice for scenes the tuning never saw (docs/model.md as of commit f3b2207, "Advice for unseen scenes"): tunes
# experiments/tune-advise.json (synthetic scenes and six OpenArena maps, as in real.json), imports
# OpenArena maps that are in neither, and advises each from that tuning with --exhaustive, which
# also measures every configuration of the tuned spaces on the map: each structure's line gives the
# map's own best (in that table, and re-measured after the choices), and the advised
# configuration's and the category's parameters' gaps to it, both on the re-measurement.
#
#   experiments/advise_unseen.sh [MAP ...]
#     default maps: oa_dm2 delta oa_dm3 oa_dm5 oa_dm6 oa_dm7 hydronex q3dm6ish (pak1-maps.pk3, brushes)
#
# Writes into RCB_ADVISE_DIR (default results/advise-unseen): the tuning (tuning-advise.json,
# .md, advise.db; kept and reused when it exists, delete it to tune again), each map's scene
# (MAP-brushes.rcbscene: 20 frames of 1% dynamics, 1000 centre rays, seed 1, as the tuning's maps),
# advise-MAP.txt (the advice) and summary.txt (every map's category and exhaustive lines).
# Environment: RCBENCH (default build/rcbench), RCB_ADVISE_DIR, RCB_REPETITIONS (measurements per
# configuration on each map, default 5), RCB_METHOD (advise --method, default auto; category gives
# the category's parameters as they are). Run scripts/fetch_maps.sh first; pin it to a core
# (taskset -c 0) on a shared machine. Takes about a minute per map beside the tuning's minute.
set -euo pipefail
cd "$(dirname "$0")/.."
rcbench=${RCBENCH:-build/rcbench}
dir=${RCB_ADVISE_DIR:-results/advise-unseen}
reps=${RCB_REPETITIONS:-5}
method=${RCB_METHOD:-auto}
maps=("$@")
if ((${#maps[@]} == 0)); then maps=(oa_dm2 delta oa_dm3 oa_dm5 oa_dm6 oa_dm7 hydronex q3dm6ish); fi
if [ ! -f data/maps/pak1-maps.pk3 ]; then
  echo "advise_unseen: data/maps/pak1-maps.pk3 is missing; run scripts/fetch_maps.sh" >&2
  exit 2
fi
mkdir -p "$dir"
tuning=$dir/tuning-advise.json
if [ ! -f "$tuning" ]; then
  "$rcbench" tune experiments/tune-advise.json --db "$dir/advise.db" --out-dir "$dir"
fi
summary=$dir/summary.txt
: >"$summary"
for map in "${maps[@]}"; do
  scene=$dir/$map-brushes.rcbscene
  if [ ! -f "$scene" ]; then
    "$rcbench" scene import data/maps/pak1-maps.pk3 --map "$map" --bsp-mode brushes --frames 20 -o "$scene" >/dev/null
  fi
  "$rcbench" advise "$scene" --tuning "$tuning" --method "$method" --exhaustive --warmup 2 \
    --repetitions "$reps" >"$dir/advise-$map.txt"
  {
    echo "== $map: $(sed -n 's/^Scene .* -> category \([^:]*\):.*/category \1/p' "$dir/advise-$map.txt")"
    sed -n '/^Every configuration of the tuned spaces/,$p' "$dir/advise-$map.txt" | tail -n +2
  } | tee -a "$summary"
done
echo "advise_unseen: wrote $summary"
