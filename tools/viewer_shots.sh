#!/usr/bin/env bash
# tools/viewer_shots.sh: the viewer's pictures in README.md and REPORT.md, made by the headless browser
# the tests use (tools/browser.py): `make demo`, then
#   viewer/screenshot.png       the demo at step 8, its fastest disk at step 0 selected, with its trail
#   bench/viewer_heating_*.png  the demo at steps 0, 8 and 60: a few fast disks heating the gas
set -euo pipefail
cd "$(dirname "$0")/.."
make -s demo > /dev/null
# the fastest disk of step 0 (the first 2000 lines)
fast=$(head -n 2000 viewer/demo.out | awk '{ s = $5 * $5 + $6 * $6; if (s > best) { best = s; i = $2 } } END { print i }')
page="file://$PWD/viewer/index.html?in=demo.in&src=demo.out"
python3 tools/browser.py shot "$page&step=8&select=$fast" viewer/screenshot.png --size 1000,760
for step in 0 8 60; do
    python3 tools/browser.py shot "$page&step=$step&frame=1" "bench/viewer_heating_$step.png" --size 760,560
done
echo "viewer/screenshot.png (disk $fast selected), bench/viewer_heating_{0,8,60}.png"
