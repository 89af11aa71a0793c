#!/usr/bin/env bash
# The README's first command: install what is missing, build (Release), and run the default job,
# experiments/quick.json: the thesis' six scenes (§6.1), every structure at its defaults. Prints the
# thesis-style table and stores everything in results/rcbench.db.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
build/rcbench run experiments/quick.json --db results/rcbench.db
echo
echo "Results: results/rcbench.db (query it: build/rcbench query results/rcbench.db \"SELECT * FROM cell_summary\")"
