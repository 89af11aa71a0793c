#!/usr/bin/env bash
# Fails when a commit after BASE has a subject longer than 72 characters (the project's rule: details
# go in the body). Subjects before BASE are history and stay as they are.
#   scripts/check_commit_subjects.sh [BASE]    (default: the commit this rule started from)
# Without git, or in a clone that does not hold BASE (a shallow or exported tree), it says so and
# passes: there is no history to check.
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-0243d18}
if ! git rev-parse --verify --quiet "$base^{commit}" >/dev/null 2>&1; then
  echo "check_commit_subjects: no commit $base in this clone; nothing to check"
  exit 0
fi
long=$(git log --format='%h %s' "$base..HEAD" | awk '{ s = $0; sub(/^[^ ]+ /, "", s) } length(s) > 72')
if [ -n "$long" ]; then
  echo "check_commit_subjects: subjects over 72 characters after $base:" >&2
  echo "$long" >&2
  exit 1
fi
echo "check_commit_subjects: $(git rev-list --count "$base..HEAD") commits after $base, every subject within 72 characters"
