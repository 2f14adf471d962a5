#!/usr/bin/env bash
# Side-by-side response calibration: monovo against OpenCV's Debevec and Robertson on the
# same synthetic sweeps (every noise level, lossless and JPEG 90; the paper's 120 exposures
# at 1280x1024 and 12 exposures at 320x256). Needs a release build of monovo and
#   pip install opencv-python-headless numpy
# Usage: xtask/peers/compare_response.sh [WORKDIR]   (prints one line per sweep and method)
#   MONOVO=PATH  the monovo binary (default: target/release/monovo)
#   SKIP_OPENCV=1  monovo's rows only (to remeasure a new build against the committed peers)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
monovo="${MONOVO:-$here/../../target/release/monovo}"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"
printf '%-14s %-16s %-10s %8s %10s %8s %10s\n' sensor sweep method max shape_rms max_250 rms_250
for noise in low typical high; do
  for store in png jpeg; do
    [ "$store" = jpeg ] && [ "$noise" = low ] && continue
    for size in big small; do
      if [ "$size" = big ]; then dims=1280x1024; frames=120; else dims=320x256; frames=12; fi
      name="$noise-$store-$size"
      sweep="$work/$name"
      extra=()
      [ "$store" = png ] && extra=(--png)
      "$monovo" synth sweep -o "$sweep" --force --seed 7 --size "$dims" --frames "$frames" \
        --noise "$noise" "${extra[@]}" > /dev/null
      "$monovo" calib response "$sweep" -o "$work/$name.monovo.txt" --force --json > /dev/null
      skip=()
      [ -n "${SKIP_OPENCV:-}" ] && skip=(--skip-opencv)
      python3 "$here/opencv_response.py" "$sweep" --json "${skip[@]}" \
        --compare-pcalib "$work/$name.monovo.txt" > "$work/$name.json"
      python3 - "$work/$name.json" "$work/$name.monovo.txt" "$noise-$store" "${dims}x$frames" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
for method, key in (("monovo", sys.argv[2]), ("debevec", "debevec"), ("robertson", "robertson")):
    if key != sys.argv[2] and key not in d:
        continue
    r = d.get(key) or {}
    fmt = lambda v: "-" if v is None else f"{v:.3f}"
    print(f"{sys.argv[3]:<14} {sys.argv[4]:<16} {method:<10} {fmt(r.get('max')):>8} {fmt(r.get('shape_rms')):>10} {fmt(r.get('max_250')):>8} {fmt(r.get('shape_rms_250')):>10}")
PY
    done
  done
done
