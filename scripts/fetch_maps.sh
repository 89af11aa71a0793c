#!/usr/bin/env bash
# Fetches the real scenes of experiments/real.json on demand, into data/ (git-ignored; never commit
# maps or models):
#   data/maps/*.pk3    OpenArena 0.8.1 maps from Debian's openarena-081-maps package (GPL-2 data)
#   data/models/...    assimp's own test models from Debian's assimp-testmodels package
# With the argument `unseen`, also:
#   data/maps-unseen/z_oacmp-volume1-v3.pk3   the maps of Debian's openarena-oacmp1 package, which
#                      no model, tuner or advice rule was designed on (experiments/tune-suite-fresh.json)
# With the argument `fresh`, also:
#   data/maps-088/pak6-patch088.pk3   the maps of Debian's openarena-088-data package, kept as a
#                      test set that no model was designed on (experiments/maps-088.json,
#                      maps-088b.json and maps-088c.json, six maps each)
# With the argument `nexuiz`, also:
#   data/maps-nexuiz/data.pk3   the maps of Debian's nexuiz-data package (Nexuiz 2.5.2, GPL-2
#                      data; a 267 MB download), another game's maps that no part of rcbench was
#                      designed, tuned or judged on before (experiments/maps-nexuiz.json,
#                      tune-suite-nexuiz.json)
# With the argument `085`, also:
#   data/maps-085/pak6-patch085.pk3   the maps of Debian's openarena-085-data package; the seven
#                      no earlier experiment named are the fresh test set of experiments/maps-085.json
# With the argument `torcs`, also:
#   data/tracks-torcs/*.ac, *.acc   the race tracks of Debian's torcs-data package (TORCS 1.3.7,
#                      GPL-2 data; a 333 MB download), each track's own AC3D mesh (the -relief
#                      helper meshes left out): the fresh test set of experiments/tracks-torcs.json
# With the argument `flightgear`, also:
#   data/models-flightgear/*.ac   the airport buildings and structures of Debian's
#                      flightgear-data-base package (FlightGear 2020.3 scenery, GPL-2 data; a 1.3 GB
#                      download): Scenery/Models/Airport/*.ac, its vehicle subfolders left out; the
#                      fresh test set of experiments/models-flightgear-airport.json
# With the argument `scenery`, also:
#   data/models-scenery/*.ac, *.obj   the fresh test set of experiments/models-scenery.json, by the
#                      rule its description gives: the largest .ac of each top-level folder of
#                      FlightGear's Scenery/Models but Airport/ (flightgear-data-base), and the
#                      largest .obj of each folder of Debian's stellarium-data (Stellarium 0.22.2,
#                      GPL-2 data; a 246 MB download)
# With the argument `ai`, also:
#   data/models-ai/*.ac   the fresh test set of experiments/models-ai.json, by the rule its
#                      description gives: of the folders of AI/Aircraft in Debian's flightgear-data-ai
#                      (FlightGear 2020.3's AI aircraft, GPL-2 data; a 287 MB download) whose largest
#                      .ac has at least 100,000 bytes, every sixth in byte order, its largest .ac
# Uses `apt-get download` (no root needed: only the .deb is fetched, nothing is installed) and
# `dpkg-deb -x` to unpack. Run it again to re-fetch; it skips what is already there.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p data/maps data/models data/.debs

fetch() {  # fetch PACKAGE UNPACK_DIR
  local pkg="$1" dir="$2"
  if [ -d "$dir" ] && [ -n "$(ls -A "$dir" 2>/dev/null)" ]; then return; fi
  ( cd data/.debs && apt-get download "$pkg" )
  mkdir -p "$dir"
  dpkg-deb -x data/.debs/"$pkg"_*.deb "$dir"
}

# largest: the largest of the files named on stdin, by size, if it has at least 100,000 bytes.
largest() { xargs -r -d '\n' stat -c '%s %n' | sort -rn | awk 'NR == 1 && $1 >= 100000 { print $2 }'; }

fetch openarena-081-maps data/.debs/openarena-081-maps
find data/.debs/openarena-081-maps -name '*.pk3' -exec cp -u {} data/maps/ \;
echo "fetch_maps: $(ls data/maps/*.pk3 | wc -l) pk3 files in data/maps/"

fetch assimp-testmodels data/.debs/assimp-testmodels
models=$(find data/.debs/assimp-testmodels -type d -path '*/models' | head -n 1)
if [ -n "$models" ]; then cp -ru "$models"/. data/models/; fi
echo "fetch_maps: $(find data/models -type f | wc -l) model files in data/models/"

if [ "${1:-}" = unseen ]; then
  fetch openarena-oacmp1 data/.debs/openarena-oacmp1
  mkdir -p data/maps-unseen
  find data/.debs/openarena-oacmp1 -name 'z_oacmp-volume1-v3.pk3' -exec cp -u {} data/maps-unseen/ \;
  echo "fetch_maps: $(ls data/maps-unseen/*.pk3 | wc -l) pk3 files in data/maps-unseen/"
fi

if [ "${1:-}" = fresh ]; then
  fetch openarena-088-data data/.debs/openarena-088-data
  mkdir -p data/maps-088
  find data/.debs/openarena-088-data -name 'pak6-patch088.pk3' -exec cp -u {} data/maps-088/ \;
  echo "fetch_maps: $(ls data/maps-088/*.pk3 | wc -l) pk3 files in data/maps-088/"
fi

if [ "${1:-}" = 085 ]; then
  fetch openarena-085-data data/.debs/openarena-085-data
  mkdir -p data/maps-085
  find data/.debs/openarena-085-data -name 'pak6-patch085.pk3' -exec cp -u {} data/maps-085/ \;
  echo "fetch_maps: $(ls data/maps-085/*.pk3 | wc -l) pk3 files in data/maps-085/"
fi

if [ "${1:-}" = torcs ]; then
  fetch torcs-data data/.debs/torcs-data
  mkdir -p data/tracks-torcs
  find data/.debs/torcs-data -path '*/games/torcs/tracks/*' \( -name '*.ac' -o -name '*.acc' \) \
    ! -name '*-relief.ac' -exec cp -u {} data/tracks-torcs/ \;
  echo "fetch_maps: $(ls data/tracks-torcs/*.ac* | wc -l) track meshes in data/tracks-torcs/"
fi

if [ "${1:-}" = nexuiz ]; then
  fetch nexuiz-data data/.debs/nexuiz-data
  mkdir -p data/maps-nexuiz
  find data/.debs/nexuiz-data -name 'data.pk3' -exec cp -u {} data/maps-nexuiz/ \;
  echo "fetch_maps: $(ls data/maps-nexuiz/*.pk3 | wc -l) pk3 files in data/maps-nexuiz/"
fi

if [ "${1:-}" = flightgear ]; then
  fetch flightgear-data-base data/.debs/flightgear-data-base
  mkdir -p data/models-flightgear
  find data/.debs/flightgear-data-base -path '*/Scenery/Models/Airport/*' -name '*.ac' \
    ! -path '*/Airport/*/*' -exec cp -u {} data/models-flightgear/ \;
  echo "fetch_maps: $(ls data/models-flightgear/*.ac | wc -l) airport models in data/models-flightgear/"
fi

if [ "${1:-}" = scenery ]; then
  fetch flightgear-data-base data/.debs/flightgear-data-base
  fetch stellarium-data data/.debs/stellarium-data
  mkdir -p data/models-scenery
  models=data/.debs/flightgear-data-base/usr/share/games/flightgear/Scenery/Models
  for folder in "$models"/*/; do
    [ "$(basename "$folder")" = Airport ] && continue
    find "$folder" -name '*.ac' | largest | xargs -r -I{} cp -u {} data/models-scenery/
  done
  find data/.debs/stellarium-data -name '*.obj' -printf '%h\n' | sort -u | while read -r folder; do
    find "$folder" -maxdepth 1 -name '*.obj' | largest | xargs -r -I{} cp -u {} data/models-scenery/
  done
  echo "fetch_maps: $(ls data/models-scenery | wc -l) models in data/models-scenery/"
fi

if [ "${1:-}" = ai ]; then
  fetch flightgear-data-ai data/.debs/flightgear-data-ai
  mkdir -p data/models-ai
  # Of AI/Aircraft's folders (byte order), those whose largest .ac has at least 100,000 bytes; of
  # these the 1st, 7th, 13th, ... (every sixth), each folder's largest .ac.
  aircraft=data/.debs/flightgear-data-ai/usr/share/games/flightgear/AI/Aircraft
  find "$aircraft" -mindepth 1 -maxdepth 1 -type d | LC_ALL=C sort | while read -r folder; do
    find "$folder" -name '*.ac' | largest
  done | awk 'NR % 6 == 1' | xargs -r -d '\n' -I{} cp -u {} data/models-ai/
  echo "fetch_maps: $(ls data/models-ai | wc -l) models in data/models-ai/"
fi
