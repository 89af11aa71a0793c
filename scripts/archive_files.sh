#!/usr/bin/env bash
# Archives a folder of outputs that are not a results database (e.g. scripts/advise_study.sh's
# advise-*.json) as a file set of the results archive (results/README.md, "File sets"):
# results/archive/files/NAME.tar.xz and its manifest NAME.json. Never replaces a file set.
#
#   scripts/archive_files.sh NAME DIR --command CMD --commit C [--note TEXT]
#
# Packs DIR's regular files except scene recordings (*.rcbscene, which the command remakes) and
# databases (*.db: archive those with `rcbench archive add`), sorted by name, with fixed owners and
# times so the same files give the same tarball. The manifest records NAME, the command (as typed,
# with when it ran and the machine's state in words), the binary's commit, this machine (CPU model,
# cores, host name), when it was archived, each file's SHA-256 and the tarball's SHA-256.
# Exit 2 for bad arguments, a missing folder, an existing file set or a dirty commit.
set -euo pipefail
die() { echo "archive_files.sh: $*" >&2; exit 2; }
(($# >= 2)) || die "usage: scripts/archive_files.sh NAME DIR --command CMD --commit C [--note TEXT]"
name=$1 dir=$2
shift 2
command="" commit="" note=""
while (($#)); do
  case "$1" in
    --command) (($# >= 2)) || die "--command needs the command"; command=$2; shift ;;
    --commit) (($# >= 2)) || die "--commit needs a commit"; commit=$2; shift ;;
    --note) (($# >= 2)) || die "--note needs a text"; note=$2; shift ;;
    *) die "$1: unknown argument" ;;
  esac
  shift
done
[[ "$name" =~ ^[A-Za-z0-9][A-Za-z0-9._-]*$ ]] || die "NAME $name: letters, digits, '.', '_', '-' only"
[[ -d "$dir" ]] || die "DIR $dir: no such folder"
[[ -n "$command" ]] || die "--command is required"
[[ "$commit" =~ ^[0-9a-f]{7,40}$ ]] || die "--commit $commit: a clean commit (hex), not a dirty or unknown tree"
command -v jq >/dev/null || die "needs jq (Debian package jq)"
cd "$(dirname "$0")/.."
out=results/archive/files
mkdir -p "$out"
[[ ! -e "$out/$name.tar.xz" && ! -e "$out/$name.json" ]] || die "$out/$name: the file set exists; archived data is added to, never edited"

mapfile -t files < <(cd "$dir" && find . -maxdepth 1 -type f ! -name '*.rcbscene' ! -name '*.db' -printf '%P\n' | LC_ALL=C sort)
((${#files[@]} > 0)) || die "DIR $dir: no file to archive"
tmp=$(mktemp "$out/.$name.XXXXXX")
trap 'rm -f "$tmp"' EXIT
chmod 644 "$tmp"
tar -C "$dir" --owner=0 --group=0 --numeric-owner --mtime=@0 -cf - "${files[@]}" | xz -9 >"$tmp"
sums=$(cd "$dir" && sha256sum "${files[@]}" | jq -R -s 'split("\n") | map(select(length > 0) | split("  ") | {(.[1]): .[0]}) | add')
jq -n --arg name "$name" --arg command "$command" --arg commit "$commit" --arg note "$note" \
  --arg cpu "$(sed -n 's/^model name[[:space:]]*: //p' /proc/cpuinfo | head -n 1)" --arg cores "$(nproc --all)" \
  --arg host "$(hostname)" --arg at "$(date -u +%FT%TZ)" --arg sha "$(sha256sum "$tmp" | cut -d' ' -f1)" \
  --argjson files "$sums" \
  '{name: $name, file: ($name + ".tar.xz"), command: $command, git_commit: $commit, note: $note,
    machine: {cpu: $cpu, cores: ($cores | tonumber), host: $host}, archived_at: $at,
    files: $files, sha256: $sha}' >"$out/$name.json.tmp"
mv -n "$tmp" "$out/$name.tar.xz"
mv -n "$out/$name.json.tmp" "$out/$name.json"
trap - EXIT
echo "archive_files.sh: wrote $out/$name.tar.xz (${#files[@]} files) and $out/$name.json"
