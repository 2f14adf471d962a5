#!/usr/bin/env python3
"""Scores vignette maps against the truth of a `monovo synth vignette` folder.

Each map is compared with truth_vignette.png over the pixels valid in both (map > 0),
after the best global scale s (least squares of s * map / truth = 1): the RMS of
s * map / truth - 1 in percent, its 99th percentile, and the valid fraction. Maps:
monovo's NAME_raw.png and NAME.png, and the authors' 2016 vignetteCalib's
vignetteCalibResult/vignette.png (its unregularised map, max pixel = 254.9^2) and
vignetteSmoothed.png (the same after four 3x3 mean filters); see
docs/reference-tools.md.

    monovo synth vignette -o wall --png --seed 3 --sensor gain --noise high --response dorf8
    monovo calib vignette wall -o wall/m.png
    (cd run && QT_QPA_PLATFORM=offscreen vignetteCalib_headless ../wall/)
    python3 xtask/peers/vignette_vs_2016.py wall wall/m.png wall/m_raw.png \
        run/vignetteCalibResult/vignette.png run/vignetteCalibResult/vignetteSmoothed.png
"""
import os
import sys

import cv2
import numpy as np


def load(path):
    a = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if a is None:
        sys.exit(f"{path}: not an image")
    return a.astype(np.float64)


def score(vmap, truth):
    valid = (vmap > 0) & (truth > 0)
    r = vmap[valid] / truth[valid]
    s = r.sum() / (r * r).sum()
    e = s * r - 1.0
    return 100 * np.sqrt(np.mean(e * e)), 100 * np.percentile(np.abs(e), 99), valid.mean()


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    truth = load(os.path.join(sys.argv[1], "truth_vignette.png"))
    print(f"{'map':<48} {'rms %':>8} {'p99 %':>8} {'valid %':>8}")
    for path in sys.argv[2:]:
        rms, p99, frac = score(load(path), truth)
        print(f"{path:<48} {rms:8.3f} {p99:8.3f} {100 * frac:8.2f}")


if __name__ == "__main__":
    main()
