#!/usr/bin/env bash
# Runs one shard of an experiment as a Slurm array task; the scheduler is yours, rcbench only splits
# the plan. Usage: sbatch --array=1-N experiments/slurm_shards.sh EXPERIMENT.json N
# Then merge: build/rcbench merge results/all.db results/shards/<name>-*.db
#SBATCH --job-name=rcbench
#SBATCH --cpus-per-task=2
#SBATCH --exclusive
#SBATCH --output=results/shards/%x-%A_%a.log
set -euo pipefail
experiment=${1:?usage: slurm_shards.sh EXPERIMENT.json N}
shards=${2:?usage: slurm_shards.sh EXPERIMENT.json N}
task=${SLURM_ARRAY_TASK_ID:?run this under sbatch --array=1-N}
name=$(basename "$experiment" .json)
mkdir -p results/shards
exec build/rcbench run "$experiment" --shard "$task/$shards" --db "results/shards/$name-$task.db"
