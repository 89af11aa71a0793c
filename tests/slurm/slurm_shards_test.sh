#!/usr/bin/env bash
# The cluster path end to end: experiments/slurm_shards.sh submits a tiny experiment as a Slurm job
# array of 3 shards plus the dependent merge job; the merged database must hold, cell for cell, what
# one process running the whole plan stores (same cell keys, scenes, configurations, and per frame
# the same dynamics, hits, ground-truth disagreements and eq. 5.4 counters n_t, n_rb, n_tp; times
# differ). Usage: slurm_shards_test.sh RCBENCH SOURCE_DIR WORK_DIR
# Runs when RCB_SLURM_TEST=1 (then a missing cluster fails it) or, unless RCB_SLURM_TEST=0, when a
# Slurm controller answers with an idle node; otherwise it exits 77, which ctest reports as skipped.
# scripts/slurm_local.sh starts a one-node cluster on this machine. RCB_SLURM_TIMEOUT (seconds,
# default 300) bounds the wait for the jobs.
set -euo pipefail
if (($# != 3)); then echo "usage: slurm_shards_test.sh RCBENCH SOURCE_DIR WORK_DIR" >&2; exit 2; fi
rcbench=$(realpath "$1")
src=$(realpath "$2")
work=$3
shards=3
timeout_s=${RCB_SLURM_TIMEOUT:-300}

fail() { echo "FAILED: $*" >&2; exit 1; }
skip() { echo "SKIPPED: $*"; exit 77; }

cluster_answers() {
  command -v sbatch >/dev/null && timeout 10 scontrol ping 2>/dev/null | grep -q UP &&
    timeout 10 sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed)$'
}
case "${RCB_SLURM_TEST:-}" in
  1) cluster_answers || fail "RCB_SLURM_TEST=1 but no Slurm controller with an idle node answers (start one: scripts/slurm_local.sh)" ;;
  0) skip "RCB_SLURM_TEST=0" ;;
  "") cluster_answers || skip "no Slurm cluster answers (scripts/slurm_local.sh starts one; RCB_SLURM_TEST=1 makes this test required)" ;;
  *) fail "RCB_SLURM_TEST=$RCB_SLURM_TEST: expected 1 (run, required) or 0 (skip)" ;;
esac

# A fresh folder of its own under WORK_DIR (the jobs must see it: keep the build tree on a shared
# file system on a real cluster); kept when the test fails.
mkdir -p "$work"
run=$(mktemp -d "$(realpath "$work")/run.XXXXXX")
cd "$run"
jobs=()
cleanup() {
  local rc=$?
  if ((${#jobs[@]})); then scancel "${jobs[@]}" 2>/dev/null || true; fi
  if ((rc == 0)); then rm -rf "$run"; else echo "(files kept in $run)" >&2; fi
}
trap cleanup EXIT

# 2 scenes x 5 configurations x 2 repetitions = 20 cells: 3 shards of 7, 7 and 6 cells.
cat >tiny.json <<'EOF'
{
  "name": "slurm-tiny",
  "frames": 3,
  "rays_per_frame": 200,
  "repetitions": 2,
  "seeds": [7],
  "scenes": [{"preset": "uni-s"}, {"generator": "irregular", "objects": 300, "ray_mix": "center:0.5,los:0.5"}],
  "structures": [
    {"name": "bf"},
    {"name": "ug", "params": {"density": [1, 4]}},
    {"name": "hg"},
    {"name": "lbvh"}
  ]
}
EOF

t0=$SECONDS
submitted=$(RCBENCH="$rcbench" RCB_SHARDS_DIR="$run/shards" RCB_MERGED_DB="$run/all.db" \
  "$src/experiments/slurm_shards.sh" submit tiny.json "$shards" --time=30) || fail "submit failed: $submitted"
echo "$submitted"
array=$(sed -n 's/^submitted job array \([0-9][0-9]*\):.*/\1/p' <<<"$submitted")
merge=$(sed -n 's/^submitted job \([0-9][0-9]*\):.*/\1/p' <<<"$submitted")
if [ -z "$array" ] || [ -z "$merge" ]; then fail "no job ids in the output of slurm_shards.sh submit"; fi
jobs=("$array" "$merge")

# The reference, one process, the whole plan, while the jobs wait or run.
"$rcbench" run tiny.json --db single.db >single.log 2>&1 || { cat single.log >&2; fail "the single-process run failed"; }

# Wait until neither job is pending, running or completing.
while :; do
  if ! left=$(squeue -h -j "$array,$merge" -o %i 2>/dev/null); then
    # Finished jobs drop out of the controller after MinJobAge; a controller that stopped answering is a failure.
    timeout 10 scontrol ping 2>/dev/null | grep -q UP || fail "the Slurm controller stopped answering"
    left=""
  fi
  [ -z "$left" ] && break
  if ((SECONDS - t0 > timeout_s)); then
    squeue -j "$array,$merge" >&2 || true
    fail "the jobs did not finish within ${timeout_s}s (RCB_SLURM_TIMEOUT)"
  fi
  sleep 1
done
jobs=()
echo "jobs finished after $((SECONDS - t0))s"

# Every array task and the merge job must have completed (a failed task cancels the merge).
states=$(scontrol -o show job "$array" 2>/dev/null; scontrol -o show job "$merge" 2>/dev/null) || true
bad=$(grep -o 'JobId=[0-9]* .*JobState=[A-Z_]*' <<<"$states" | grep -v 'JobState=COMPLETED$' | sed 's/ .*JobState=/: /') || true
if [ -n "$bad" ] || [ ! -f all.db ]; then
  for f in shards/*.log; do [ -r "$f" ] && { echo "--- $f"; tail -n 20 "$f"; }; done >&2
  fail "jobs not completed: ${bad:-merge wrote no all.db}"
fi

q() { "$rcbench" query "$1" --csv "$2"; }
# One finished run per shard, K/3 for K = 1..3.
runs=$(q all.db "SELECT shard, finished_at IS NOT NULL FROM run ORDER BY shard")
[ "$runs" = "$(printf 'shard,finished_at IS NOT NULL\n1/3,1\n2/3,1\n3/3,1')" ] || fail "runs in all.db: $runs"

# Cell for cell, frame for frame; LEFT JOIN keeps a cell that lost its frames.
cells="SELECT cell.cell_key, scene.hash, scene.name, config.structure, config.params, cell.repetition, cell.objects,
  cell.verified, cell.mismatches, cell.frames, cell.memory_bytes, frame.frame, frame.warmup, frame.inserts, frame.removes,
  frame.moves, frame.rays, frame.hits, frame.missed, frame.extra, frame.duplicate, frame.n_t, frame.n_rb, frame.n_tp,
  frame.memory_bytes, frame.sah_cost
  FROM cell JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id
  LEFT JOIN frame ON frame.cell_id = cell.id ORDER BY cell.cell_key, frame.frame"
q single.db "$cells" >single.csv
q all.db "$cells" >all.csv
n_cells=$(q single.db "SELECT count(*) FROM cell" | sed -n 2p)
[ "$n_cells" = 20 ] || fail "the single-process run stored $n_cells cells, expected 20"
if ! diff -u single.csv all.csv >diff.txt; then
  head -n 40 diff.txt >&2
  fail "the merged shards differ from the single-process run (diff above, single.csv vs all.csv)"
fi
echo "PASSED: $shards shards merged = single run: $n_cells cells, $(($(wc -l <all.csv) - 1)) frames, in $((SECONDS - t0))s"
