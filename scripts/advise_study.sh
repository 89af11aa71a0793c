#!/usr/bin/env bash
# advise against its budget-matched baselines on every OpenArena map (docs/model.md, "Advice and its budgets"):
# runs `rcbench advise MAP --tuning T --exhaustive --json` on each map of data/maps/*.pk3 and
# summarises, per map and tuned structure, each method's budget (configurations timed / counting
# replays) and its regret: advise, advise's steps taken on the map's table (advise-table), the
# pure-model choice, the category's parameters and the random and descent baselines (advise's
# timed configurations and replays). Every method and the map's optimum are chosen on one
# exhaustive table and scored on a re-measurement taken after it (regret: the choice's re-measured
# cost / the optimum's re-measured cost − 1), so none is priced by the numbers it chose on. The
# pure model is pure only where its replays timed no update ("update timed" 0: the tuning holds the
# update's prices). Then, over the maps the tuning did not see, how often each is within 5 % of the
# re-measured optimum and how often advise (either way) beats each baseline.
#
#   scripts/advise_study.sh [MAP ...]
#     default maps: every map of every data/maps/*.pk3 (as `rcbench scene maps` lists them)
#   scripts/advise_study.sh --summarize DIR [DIR ...]
#     times nothing: the summary of the advise-*.json a study left in each DIR, every map named with
#     its import mode (an archived study's figure, docs/figures.json)
#
# Environment: RCBENCH (default build/rcbench), RCB_MAPS_DIR (default data/maps), RCB_STUDY_DIR
# (default results/advise-study), RCB_TUNING (a tuning result; default
# RCB_STUDY_DIR/tuning-advise.json, tuned from experiments/tune-advise.json, which reads
# data/maps, when missing), RCB_CATEGORY (advise --category; default: chosen from each map's
# features), RCB_SEEN (maps the tuning saw, space-separated; default the maps of
# experiments/tune-advise.json when RCB_TUNING is unset, else none), RCB_REPETITIONS (default 5),
# RCB_SEED (advise --seed, the random baseline's; default the tuning's search seed), RCB_ADVISE_ARGS
# (more advise options, split at spaces, e.g. "--verify-top 1 --refine 8"), RCB_BSP_MODE (how each
# map is imported: brushes, the default, or triangles), RCB_MODELS_DIR (a folder of model files assimp
# reads, e.g. data/models-scenery: its models take the maps' place, each named by its file name
# without the extension and imported as triangles; the MAP arguments then name models).
# Writes RCB_STUDY_DIR/MAP-MODE.rcbscene (20 frames of 1% dynamics, seed 1, kept and reused),
# advise-MAP.json and summary.txt (tab-separated). Needs jq (scripts/setup.sh installs it). Pin it to an idle core (taskset -c 0):
# every map measures each tuned space whole.
set -euo pipefail
fail() {
  echo "advise_study: $*" >&2
  exit 2
}
command -v jq >/dev/null || fail "needs jq (Debian package jq) to read advise's JSON"

# summarize SEEN MODE FILE...: one line per map and tuned structure, then the unseen maps' totals.
# MODE is stripped from the map names (empty: the names keep it).
summarize() {
  local seen=$1 mode=$2
  shift 2
  jq -r -s --arg seen " $seen " --arg mode "$mode" '
  def pct: (. * 1000 | round / 10 | tostring) + "%";
  [ .[] | (.scene | sub(".*/"; "") | if $mode == "" then sub(".rcbscene$"; "") else sub("-" + $mode + ".rcbscene$"; "") end) as $map
        | .exhaustive[] | {map: $map, seen: ($seen | contains(" " + $map + " ")), structure,
                           budget, regret: (.methods | map({(.method): .regret}) | add),
                           spent: (.methods | map({(.method): "\(.timed)/\(.replays)"}) | add)} ] as $rows
  | ($rows | map(select(.seen | not))) as $unseen
  | def opt: if . == null then "-" else pct end;
    ["map", "seen", "structure", "timed/replays", "update timed", "space", "advise", "advise-table", "model",
     "category", "random", "descent", "random timed/replays", "descent timed/replays"],
    ($rows[] | [.map, (if .seen then "yes" else "no" end), .structure,
                "\(.budget.timed)/\(.budget.replays)", .budget.replays_update_timed, .budget.space,
                (.regret.advise | pct), (.regret["advise-table"] | opt), (.regret.model | opt),
                (.regret.category | opt), (.regret.random | pct), (.regret.descent | pct),
                .spent.random, .spent.descent]),
    [],
    ["unseen (map x structure): \($unseen | length)"],
    (["advise", "advise-table", "model", "category", "random", "descent"][] as $m
      | ($unseen | map(.regret[$m] | select(. != null))) as $r
      | ["\($m): within 5% of the optimum in \($r | map(select(. <= 0.05)) | length) of \($r | length)"]),
    (["advise", "advise-table"][] as $a | ["random", "descent"][] as $b
      | ($unseen | map(select(.regret[$a] != null))) as $u
      | ["\($a) vs \($b): better in \($u | map(select(.regret[$a] < .regret[$b])) | length), tied in \($u | map(select(.regret[$a] == .regret[$b])) | length), worse in \($u | map(select(.regret[$a] > .regret[$b])) | length)"])
  | @tsv' "$@"
}

if [ "${1:-}" = --summarize ]; then
  shift
  (($# > 0)) || fail "--summarize needs the study folders"
  files=()
  for d in "$@"; do
    [ -d "$d" ] || fail "--summarize $d: no such folder"
    found=("$d"/advise-*.json)
    [ -e "${found[0]}" ] || fail "--summarize $d: no advise-*.json in it"
    files+=("${found[@]}")
  done
  summarize "" "" "${files[@]}"
  exit 0
fi

cd "$(dirname "$0")/.."
rcbench=${RCBENCH:-build/rcbench}
dir=${RCB_STUDY_DIR:-results/advise-study}
reps=${RCB_REPETITIONS:-5}
mode=${RCB_BSP_MODE:-brushes}
[ "$mode" = brushes ] || [ "$mode" = triangles ] || fail "RCB_BSP_MODE=$mode: not brushes or triangles"
[ -x "$rcbench" ] || fail "$rcbench is not an executable; build it or set RCBENCH"
shopt -s nullglob
# source_of[NAME]: the pk3 holding map NAME, or model NAME's file; import_args NAME: how to import it.
declare -A source_of
if [ -n "${RCB_MODELS_DIR:-}" ]; then
  [ -d "$RCB_MODELS_DIR" ] || fail "RCB_MODELS_DIR=$RCB_MODELS_DIR: no such folder"
  mode=triangles
  for file in "$RCB_MODELS_DIR"/*; do [ -f "$file" ] && source_of[$(basename "${file%.*}")]=$file; done
  ((${#source_of[@]} > 0)) || fail "RCB_MODELS_DIR=$RCB_MODELS_DIR holds no model file"
  import_args() { echo --model-mode triangles; }
else
  pk3s=("${RCB_MAPS_DIR:-data/maps}"/*.pk3)
  ((${#pk3s[@]} > 0)) || fail "no ${RCB_MAPS_DIR:-data/maps}/*.pk3; run scripts/fetch_maps.sh"
  # Each pk3's maps, by the names import's --map takes.
  for pk3 in "${pk3s[@]}"; do
    while read -r m; do source_of[$m]=$pk3; done < <("$rcbench" scene maps "$pk3")
  done
  import_args() { echo --map "$1" --bsp-mode "$mode"; }
fi
mkdir -p "$dir"
maps=("$@")
if ((${#maps[@]} == 0)); then mapfile -t maps < <(printf '%s\n' "${!source_of[@]}" | sort); fi

for map in "${maps[@]}"; do [ -n "${source_of[$map]:-}" ] || fail "no map or model $map"; done

tuning=${RCB_TUNING:-}
seen=${RCB_SEEN-}
if [ -z "$tuning" ]; then
  tuning=$dir/tuning-advise.json
  [ -f "$tuning" ] || "$rcbench" tune experiments/tune-advise.json --db "$dir/advise.db" --out-dir "$dir"
  [ -n "${RCB_SEEN+set}" ] || seen=$(jq -r '.. | objects | .map? // empty' experiments/tune-advise.json | tr '\n' ' ')
fi
[ -f "$tuning" ] || fail "$tuning: no such tuning result"

extra=()
[ -z "${RCB_CATEGORY:-}" ] || extra+=(--category "$RCB_CATEGORY")
[ -z "${RCB_SEED:-}" ] || extra+=(--seed "$RCB_SEED")
if [ -n "${RCB_ADVISE_ARGS:-}" ]; then
  read -r -a more <<<"$RCB_ADVISE_ARGS"
  extra+=("${more[@]}")
fi
for map in "${maps[@]}"; do
  scene=$dir/$map-$mode.rcbscene
  # shellcheck disable=SC2046 # import_args prints separate words, none with spaces
  [ -f "$scene" ] || "$rcbench" scene import "${source_of[$map]}" $(import_args "$map") --frames 20 -o "$scene" >/dev/null
  "$rcbench" advise "$scene" --tuning "$tuning" --exhaustive --json --warmup 2 --repetitions "$reps" \
    "${extra[@]}" >"$dir/advise-$map.json"
done

files=()
for map in "${maps[@]}"; do files+=("$dir/advise-$map.json"); done
summarize "$seen" "$mode" "${files[@]}" | tee "$dir/summary.txt"
echo "advise_study: wrote $dir/summary.txt"
