#!/usr/bin/env bash
# Refresh the web console's vendored front-end libraries (service/api/ui/static/vendor/) from the npm
# registry: the built files and each library's licence, nothing else. Run after editing the versions in
# service/api/ui/package.json; commit the result. The console never loads anything from another host.
set -euo pipefail
cd "$(dirname "$0")/.."
UI=service/api/ui
OUT=$UI/static/vendor
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
cp "$UI/package.json" "$TMP/"
(cd "$TMP" && npm install --no-audit --no-fund --ignore-scripts --omit=dev >/dev/null)
rm -rf "$OUT" && mkdir -p "$OUT/uplot" "$OUT/d3-celestial/lib" "$OUT/d3-celestial/data"
M=$TMP/node_modules
cp "$M/uplot/dist/uPlot.iife.min.js" "$M/uplot/dist/uPlot.min.css" "$M/uplot/LICENSE" "$OUT/uplot/"
C=$M/d3-celestial
cp "$C/celestial.min.js" "$C/celestial.css" "$C/LICENSE" "$OUT/d3-celestial/"
cp "$C/lib/d3.min.js" "$C/lib/d3.geo.projection.min.js" "$OUT/d3-celestial/lib/"
# d3 v3 ships inside d3-celestial; the d3@3 package (same version) is installed for its licence only
cp "$M/d3/LICENSE" "$OUT/d3-celestial/lib/LICENSE.d3"
# data: bright stars (V <= 6), constellation lines and names; the Milky Way, bright DSOs and planets
# files are loaded by Celestial.display() whatever it shows (mw.json is required), so they ship too
for f in stars.6 constellations.lines constellations mw dsos.bright planets starnames dsonames; do
  cp "$C/data/$f.json" "$OUT/d3-celestial/data/"
done
for pkg in uplot d3-celestial d3; do
  node -e "const p=require('$M/$pkg/package.json');console.log(p.name+' '+p.version+' '+p.license)"
done > "$OUT/VERSIONS"
cat "$OUT/VERSIONS"
