#!/usr/bin/env bash
# Regenerates the docs' figures from the results archive, with no timing (results/README.md).
#
#   scripts/reproduce.sh [--check] [--root DIR] [--rcbench BIN] [--shard K/N] [FIGURE...]
#
# docs/figures.json is the registry: each figure's name, the doc that shows it, the archived exports
# it reads (results/archive/NAME.db.xz), optionally the archived file sets it reads
# (results/archive/files/NAME.tar.xz, outputs that are not a results database, such as advise's
# JSON), the commands that make it (a word {NAME} stands for that export, unpacked, or that file
# set's folder) and its format (markdown as printed, or text in a code block). The
# figure is the last command's standard output; earlier commands prepare (e.g. `fit` before
# `findings`). Each figure gets fresh copies of its exports, so figures do not depend on each
# other's order. Only reading and analysing commands may run: nothing here times anything.
#
# In the doc the figure sits between two lines of its own:
#   <!-- figure: NAME -->
#   ... generated, do not edit ...
#   <!-- /figure -->
# Without --check the script writes each figure there; with --check it writes nothing and fails
# (exit 1) naming every figure whose text differs from its regenerated output. Either way it fails
# when a doc marks a figure the registry does not have (a figure without archived data leaves the
# docs), when a registered figure has no markers, when a table of measured numbers stands outside
# a figure (below), or when an export does not match its manifest.
# --root: the checkout whose docs/, README.md and results/ are used (default: this script's);
# --rcbench: the binary (default ROOT/build/rcbench); --shard K/N: only the figures whose place in
# the registry, counted from 0, leaves K-1 when divided by N (the checks above still cover every
# doc), so that ctest runs the figures as N tests side by side. Exit 2 for bad arguments or registry.
set -euo pipefail

usage() { sed -n '4p' "$0" | sed 's/^# *//'; }
die() { echo "reproduce.sh: $*" >&2; exit 2; }

check=0
root="$(cd "$(dirname "$0")/.." && pwd)"
rcbench=""
selected=()
shard=1 shards=1
while (($#)); do
  case "$1" in
    --check) check=1 ;;
    --root) [[ $# -ge 2 ]] || die "--root needs a folder"; root="$2"; shift ;;
    --rcbench) [[ $# -ge 2 ]] || die "--rcbench needs a file"; rcbench="$2"; shift ;;
    --shard)
      [[ $# -ge 2 && "$2" =~ ^([1-9][0-9]*)/([1-9][0-9]*)$ ]] && ((BASH_REMATCH[1] <= BASH_REMATCH[2])) ||
        die "--shard needs K/N with 1 <= K <= N, got '${2:-}'"
      shard=${BASH_REMATCH[1]} shards=${BASH_REMATCH[2]}; shift ;;
    -h|--help) echo "usage: $(usage)"; exit 0 ;;
    -*) die "$1: unknown option (usage: $(usage))" ;;
    *) selected+=("$1") ;;
  esac
  shift
done
[[ -d "$root" ]] || die "--root $root: no such folder"
root="$(cd "$root" && pwd)"
rcbench="${rcbench:-$root/build/rcbench}"
[[ -x "$rcbench" && -f "$rcbench" ]] || die "--rcbench $rcbench: not an executable file (build rcbench first)"
rcbench="$(cd "$(dirname "$rcbench")" && pwd)/$(basename "$rcbench")"
command -v jq >/dev/null || die "jq is needed (Debian package jq; scripts/setup.sh installs it)"
registry="$root/docs/figures.json"
archive="$root/results/archive"
[[ -f "$registry" ]] || die "$registry: no figure registry"
jq -e '.figures | type == "array"' "$registry" >/dev/null 2>&1 || die "$registry: expected {\"figures\": [...]}"

# The registry's figures, each checked for the fields the loop below reads.
mapfile -t names < <(jq -r '.figures[].name' "$registry")
for i in "${!names[@]}"; do
  jq -e --argjson i "$i" '.figures[$i] | (.name | type == "string" and test("^[A-Za-z0-9][A-Za-z0-9._-]*$"))
      and (.doc | type == "string") and (.format == "markdown" or .format == "text")
      and (.exports | type == "array" and all(type == "string"))
      and ((.files // []) | type == "array" and all(type == "string"))
      and (.commands | type == "array" and length > 0 and all(type == "array" and length > 0 and all(type == "string")))' \
      "$registry" >/dev/null || die "$registry: figures[$i]: needs name, doc, format (markdown or text), exports and commands"
done
[[ $(printf '%s\n' "${names[@]}" | sort | uniq -d | head -1) == "" ]] || die "$registry: a figure name appears twice"
for f in "${selected[@]}"; do
  printf '%s\n' "${names[@]}" | grep -qxF -- "$f" || die "$f: no such figure in $registry"
done

# The exports must be as archived (never edited); list them.
if ! verify_out="$("$rcbench" archive verify "$archive" 2>&1)"; then
  echo "reproduce.sh: the archive does not verify:" >&2
  echo "$verify_out" >&2
  exit 1
fi

# The file sets must be as archived: each NAME.tar.xz has the SHA-256 its manifest NAME.json records.
files_dir="$archive/files"
while IFS= read -r f; do
  [[ -f "$files_dir/$f.tar.xz" && -f "$files_dir/$f.json" ]] ||
    { echo "reproduce.sh: file set $f: needs results/archive/files/$f.tar.xz and its manifest $f.json" >&2; exit 1; }
  want="$(jq -r '.sha256 // empty' "$files_dir/$f.json")"
  have="$(sha256sum "$files_dir/$f.tar.xz" | cut -d' ' -f1)"
  [[ "$want" == "$have" ]] ||
    { echo "reproduce.sh: file set $f: results/archive/files/$f.tar.xz does not have the SHA-256 its manifest records" >&2; exit 1; }
done < <(jq -r '[.figures[] | (.files // [])[]] | unique[]' "$registry")

# Every marker in the docs names a registered figure in the doc the registry gives it.
docs=()
for d in "$root/README.md" "$root/results/README.md"; do [[ -f "$d" ]] && docs+=("$d"); done
if [[ -d "$root/docs" ]]; then mapfile -t -O "${#docs[@]}" docs < <(find "$root/docs" -name '*.md' | sort); fi
bad=0
for d in "${docs[@]}"; do
  rel="${d#"$root"/}"
  while IFS= read -r marked; do
    [[ -n "$marked" ]] || continue
    doc_of="$(jq -r --arg n "$marked" '.figures[] | select(.name == $n) | .doc' "$registry")"
    if [[ -z "$doc_of" ]]; then
      echo "reproduce.sh: $rel marks figure $marked, which docs/figures.json does not register: a figure without archived data leaves the docs" >&2
      bad=1
    elif [[ "$doc_of" != "$rel" ]]; then
      echo "reproduce.sh: $rel marks figure $marked, which docs/figures.json places in $doc_of" >&2
      bad=1
    fi
  done < <(sed -n 's/^<!-- figure: \(.*\) -->$/\1/p' "$d")
done

# A table of measured numbers outside a figure has no archived data behind it: in the same docs as
# the markers (docs/**/*.md, README.md, results/README.md), a markdown table (lines starting with
# `|`, outside code blocks and figures) fails, naming its first such line, when a cell holds a
# number followed by a time unit (ns, us, µs, ms), a percent sign or a ratio sign (× or x), or when
# its header names such a unit, ÷ or "ratio" and a later row holds a decimal number. A table of
# constants (parameters, defaults, formats) takes the line `<!-- not-a-figure -->` just before it.
for d in "${docs[@]}"; do
  LC_ALL=C awk -v rel="${d#"$root"/}" '
    /^<!-- figure: .* -->$/ { fig = 1; next }
    fig && $0 == "<!-- /figure -->" { fig = 0; next }
    fig { next }
    /^ *(```|~~~)/ { fence = !fence; row = 0; last = "```"; next }
    fence { next }
    /^ *\|/ {
      if (!row) {
        row = 1; exempt = (last == "<!-- not-a-figure -->"); told = 0
        unit_head = match($0, /(^|[^A-Za-z])(ns|us|\302\265s|ms|ratio)([^A-Za-z]|$)|%|\303\227|\303\267/)
      } else if (unit_head && match($0, /[0-9]\.[0-9]/)) measured = 1
      if (match($0, /[0-9](( ?(ns|us|\302\265s|ms|%))|\303\227|x)([^A-Za-z0-9]|$)/)) measured = 1
      if (!exempt && !told && measured) {
        printf "reproduce.sh: %s:%d: a table of measured numbers outside a figure (archive its data and register it in docs/figures.json, or mark a table of constants <!-- not-a-figure -->)\n", rel, NR
        told = 1; bad = 1
      }
      measured = 0; last = "|"; next
    }
    { row = 0 }
    NF { last = $0; sub(/^[ \t]+/, "", last) }
    END { exit bad }' "$d" >&2 || bad=1
done
((bad == 0)) || exit 1

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# One figure's regenerated text into $work/NAME/figure.md.
regenerate() {
  local i="$1" name="$2" dir="$work/$2" e n c w
  # Called in an if: set -e does not stop here, so every step says when it fails.
  mkdir "$dir" || return 1
  while IFS= read -r e; do
    "$rcbench" archive unpack "$archive/$e.db.xz" -o "$dir/$e.db" >/dev/null || {
      echo "reproduce.sh: figure $name: cannot unpack export $e" >&2
      return 1
    }
  done < <(jq -r --argjson i "$i" '.figures[$i].exports[]' "$registry")
  while IFS= read -r e; do
    mkdir "$dir/$e" && tar -xJf "$files_dir/$e.tar.xz" -C "$dir/$e" || {
      echo "reproduce.sh: figure $name: cannot unpack file set $e" >&2
      return 1
    }
  done < <(jq -r --argjson i "$i" '(.figures[$i].files // [])[]' "$registry")
  n="$(jq --argjson i "$i" '.figures[$i].commands | length' "$registry")"
  for ((c = 0; c < n; c++)); do
    local words=()
    mapfile -d '' words < <(jq -j --argjson i "$i" --argjson c "$c" '.figures[$i].commands[$c][] | . + "\u0000"' "$registry")
    local run=("$rcbench")
    case "${words[0]}" in
      fit|validate|findings|compare|query|history|categories|report) ;;
      advise-summary) run=("$root/scripts/advise_study.sh" --summarize); words=("${words[@]:1}") ;;
      *) die "figure $name: ${words[0]} is not a reading command (rcbench fit, validate, findings, compare, query, history, categories, report; advise-summary)" ;;
    esac
    while IFS= read -r e; do
      for w in "${!words[@]}"; do words[w]="${words[w]//\{$e\}/$e.db}"; done
    done < <(jq -r --argjson i "$i" '.figures[$i].exports[]' "$registry")
    while IFS= read -r e; do
      for w in "${!words[@]}"; do words[w]="${words[w]//\{$e\}/$e}"; done
    done < <(jq -r --argjson i "$i" '(.figures[$i].files // [])[]' "$registry")
    if ! (cd "$dir" && "${run[@]}" "${words[@]}") >"$dir/out" 2>"$dir/err"; then
      echo "reproduce.sh: figure $name: ${run[*]} ${words[*]} failed:" >&2
      cat "$dir/err" >&2
      return 1
    fi
  done
  [[ -s "$dir/out" ]] || { echo "reproduce.sh: figure $name: its command printed nothing" >&2; return 1; }
  if [[ "$(jq -r --argjson i "$i" '.figures[$i].format' "$registry")" == text ]]; then
    { echo '```text'; cat "$dir/out"; [[ "$(tail -c1 "$dir/out")" == "" ]] || echo; echo '```'; } >"$dir/figure.md"
  else
    { cat "$dir/out"; [[ "$(tail -c1 "$dir/out")" == "" ]] || echo; } >"$dir/figure.md"
  fi
}

failed=()
for i in "${!names[@]}"; do
  name="${names[$i]}"
  if ((${#selected[@]})) && ! printf '%s\n' "${selected[@]}" | grep -qxF -- "$name"; then continue; fi
  ((i % shards == shard - 1)) || continue
  rel="$(jq -r --argjson i "$i" '.figures[$i].doc' "$registry")"
  doc="$root/$rel"
  open="<!-- figure: $name -->"
  close="<!-- /figure -->"
  if [[ ! -f "$doc" ]] || [[ $(grep -cxF -- "$open" "$doc") != 1 ]] ||
     ! awk -v o="$open" -v c="$close" '$0 == o {on = 1; next} on && $0 == c {found = 1; exit} END {exit !found}' "$doc"; then
    echo "reproduce.sh: figure $name: $rel needs one line '$open' and, after it, a line '$close'" >&2
    failed+=("$name")
    continue
  fi
  started=$SECONDS
  if ! regenerate "$i" "$name"; then failed+=("$name"); continue; fi
  awk -v o="$open" -v c="$close" '$0 == o {on = 1; next} on && $0 == c {exit} on {print}' "$doc" >"$work/$name/current.md"
  if cmp -s "$work/$name/current.md" "$work/$name/figure.md"; then
    echo "figure $name ($rel): as regenerated ($((SECONDS - started)) s)"
  elif ((check)); then
    echo "reproduce.sh: figure $name in $rel differs from its regenerated output (scripts/reproduce.sh $name rewrites it):" >&2
    diff -u --label "$rel (figure $name)" --label regenerated "$work/$name/current.md" "$work/$name/figure.md" | head -40 >&2 || true
    failed+=("$name")
  else
    awk -v o="$open" -v c="$close" -v f="$work/$name/figure.md" '
      $0 == o {print; while ((getline line < f) > 0) print line; skip = 1; next}
      skip && $0 == c {skip = 0}
      !skip {print}' "$doc" >"$work/$name/doc.md"
    cat "$work/$name/doc.md" >"$doc"
    echo "figure $name ($rel): rewritten ($((SECONDS - started)) s)"
  fi
done
if ((${#failed[@]})); then
  echo "reproduce.sh: ${#failed[@]} figure(s) failed: ${failed[*]}" >&2
  exit 1
fi
