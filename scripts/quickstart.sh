#!/usr/bin/env bash
# The README's first command: install what is missing, build (Release), and run the default job:
# generate the thesis' six scenes (§6.1), simulate every registered structure on each, print the
# thesis-style tables and keep everything under results/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh

mkdir -p results/scenes
scenes=()
for preset in uni-s uni-m uni-l irreg-s irreg-m irreg-l; do
  build/rcbench scene gen --preset "$preset" --seed 1 -o "results/scenes/$preset.rcbscene"
  scenes+=(--scene "results/scenes/$preset.rcbscene")
done
build/rcbench simulate "${scenes[@]}" --structure all --json-out results/default-job.jsonl | tee results/default-job.txt
echo
echo "Per-run results (one JSON object per line): results/default-job.jsonl"
