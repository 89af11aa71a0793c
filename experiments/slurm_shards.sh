#!/usr/bin/env bash
# An experiment as a Slurm job array: task K of N runs shard K/N of the plan (every N-th cell from the
# K-th) into its own database, then one job merges the N shards. The scheduler is yours; rcbench only
# splits the plan. Run from the folder that holds build/ and results/ (the jobs start there too, so it
# must be on a file system the compute nodes share).
#
#   experiments/slurm_shards.sh submit EXPERIMENT.json N [sbatch options...]
#     checks the experiment, submits the array and a merge job that starts once every task has
#     succeeded (afterok; a failed task cancels it), and prints the job ids.
# The same by hand:
#   sbatch --array=1-N experiments/slurm_shards.sh EXPERIMENT.json N
#   sbatch --dependency=afterok:ARRAY_JOB_ID experiments/slurm_shards.sh --merge EXPERIMENT.json N
# (--merge also runs outside Slurm.) A task that failed or was killed is rerun with
# `sbatch --array=K ...`: it resumes its shard's unfinished run. Then merge again.
#
# Shard K writes results/shards/NAME-K.db (NAME: the experiment file's stem); the merge writes
# results/NAME.db (runs already there are kept, runs merged before are skipped). Logs:
# results/shards/rcbench-NAME-JOBID_K.log with `submit`, results/rcbench-JOBID_K.log by hand (Slurm
# opens the log before the script runs, so its folder must exist already). Environment, passed on
# to the jobs: RCBENCH (default build/rcbench), RCB_SHARDS_DIR (default results/shards),
# RCB_MERGED_DB (default results/NAME.db).
#
# Whole nodes (--exclusive), so that no other job disturbs the timings; 2 CPUs per task (raise
# --cpus-per-task for an experiment with "threads" above 2). Options given to sbatch override these.
#SBATCH --job-name=rcbench
#SBATCH --cpus-per-task=2
#SBATCH --exclusive
#SBATCH --output=results/%x-%A_%a.log
set -euo pipefail

usage="usage: slurm_shards.sh [submit | --merge] EXPERIMENT.json N (see the header)"
mode=shard
case "${1:-}" in
  submit) mode=submit; shift ;;
  --merge) mode=merge; shift ;;
esac
if (($# < 2)); then echo "slurm_shards: $usage" >&2; exit 2; fi
experiment=$1
shards=$2
shift 2
if ! [[ $shards =~ ^[1-9][0-9]{0,8}$ ]]; then echo "slurm_shards: N=$shards: expected a positive whole number" >&2; exit 2; fi
if [ "$mode" != submit ] && (($#)); then echo "slurm_shards: unexpected arguments after N: $* ($usage)" >&2; exit 2; fi
rcbench=${RCBENCH:-build/rcbench}
dir=${RCB_SHARDS_DIR:-results/shards}
name=$(basename "$experiment" .json)
merged=${RCB_MERGED_DB:-results/$name.db}

case "$mode" in
  shard)
    if [ -z "${SLURM_ARRAY_TASK_ID:-}" ]; then
      echo "slurm_shards: not an array task: sbatch --array=1-$shards $0 $experiment $shards, or: $0 submit $experiment $shards" >&2
      exit 2
    fi
    task=$SLURM_ARRAY_TASK_ID
    if ((task < 1 || task > shards)); then
      echo "slurm_shards: array task $task is outside 1..$shards (submit with --array=1-$shards)" >&2
      exit 2
    fi
    mkdir -p "$dir"
    echo "slurm_shards: shard $task/$shards of $experiment on $(hostname) -> $dir/$name-$task.db"
    exec "$rcbench" run "$experiment" --shard "$task/$shards" --db "$dir/$name-$task.db"
    ;;

  merge)
    # Exactly shards 1..N (a glob would also take shards left from a run with another N), each of
    # which must hold a finished run of shard K/N: an unfinished one means its task failed or is
    # still running, and merging it would give a database with holes.
    inputs=()
    problems=()
    for ((k = 1; k <= shards; ++k)); do
      db=$dir/$name-$k.db
      if [ ! -f "$db" ]; then
        problems+=("$db is missing")
        continue
      fi
      finished=$("$rcbench" query "$db" --csv \
        "SELECT finished_at IS NOT NULL FROM run WHERE shard = '$k/$shards' ORDER BY id DESC LIMIT 1" | sed -n 2p)
      case "$finished" in
        1) inputs+=("$db") ;;
        0) problems+=("$db: the run of shard $k/$shards is unfinished (rerun it: sbatch --array=$k ...)") ;;
        *) problems+=("$db holds no run of shard $k/$shards") ;;
      esac
    done
    if ((${#problems[@]})); then
      printf 'slurm_shards: cannot merge: %s\n' "${problems[@]}" >&2
      exit 1
    fi
    mkdir -p "$(dirname "$merged")"
    "$rcbench" merge "$merged" "${inputs[@]}"
    echo "slurm_shards: merged $shards shards of $experiment into $merged"
    ;;

  submit)
    command -v sbatch >/dev/null || { echo "slurm_shards: sbatch not found: is this a Slurm login node?" >&2; exit 1; }
    [ -x "$rcbench" ] || { echo "slurm_shards: $rcbench is not an executable (build it, or set RCBENCH)" >&2; exit 2; }
    # A bad experiment file fails here, once, rather than in N tasks.
    plan=$("$rcbench" run "$experiment" --dry-run)
    cells=$(sed -n '1s/.* = \([0-9]*\) cells.*/\1/p' <<<"$plan")
    echo "${plan%%$'\n'*}"
    if [ -n "$cells" ] && ((shards > cells)); then
      echo "slurm_shards: N=$shards is more than the $cells cells of the plan: use at most $cells tasks" >&2
      exit 2
    fi
    mkdir -p "$dir"
    self=$(realpath "$0")
    array=$(sbatch --parsable --job-name="rcbench-$name" --array="1-$shards" --output="$dir/%x-%A_%a.log" "$@" \
      "$self" "$experiment" "$shards")
    array=${array%%;*}
    merge=$(sbatch --parsable --job-name="rcbench-$name-merge" --dependency="afterok:$array" --kill-on-invalid-dep=yes \
      --output="$dir/%x-%j.log" "$@" "$self" --merge "$experiment" "$shards")
    merge=${merge%%;*}
    echo "submitted job array $array: $shards shards of $experiment into $dir/$name-K.db, logs $dir/rcbench-$name-${array}_K.log"
    echo "submitted job $merge: merges them into $merged once every shard has succeeded, log $dir/rcbench-$name-merge-$merge.log"
    echo "watch: squeue -j $array,$merge    cancel: scancel $array $merge"
    ;;
esac
