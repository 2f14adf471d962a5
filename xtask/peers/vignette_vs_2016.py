#!/usr/bin/env python3
"""Scores vignette maps against the truth of a `monovo synth vignette` folder.

Each map is compared with truth_vignette.png over the pixels valid in both (map > 0),
after the best global scale s (least squares of s * map / truth = 1): the RMS of
s * map / truth - 1 in percent, its 99th percentile, the valid fraction, and the
correlation of the errors of horizontal neighbours (after a high-pass: the error minus
its Gaussian blur of 4 px, over the pixels 3 px or more inside the image). Maps:
monovo's NAME_raw.png and NAME.png, and the authors' 2016 vignetteCalib's
vignetteCalibResult/vignette.png (its unregularised map, max pixel = 254.9^2) and
vignetteSmoothed.png (the same after four 3x3 mean filters); see
docs/reference-tools.md.

The 2016 raw map is not per-pixel: vignetteCalib reads the image bilinearly at each plane
point's position and spreads the observation bilinearly over the four pixels around it.
Over uniformly spread positions, a pixel's noise then enters its own V with weight
E[(1-f)^2] + E[f^2] = 2/3 and each neighbour's with E[f (1-f)] = 1/6, in each direction:
the per-pixel estimate filtered with [1/6 2/3 1/6] x [1/6 2/3 1/6] (half the noise of
white noise, neighbour correlation 0.41). monovo's NAME_raw.png is sampled so too; its
per-pixel map is NAME.png written with --smoothing 0. Maps given after
--through-2016-kernel are scored after that filter as well (for a per-pixel map).

    monovo synth vignette -o wall --png --seed 3 --sensor gain --noise high --response dorf8
    monovo calib vignette wall -o wall/m.png
    monovo calib vignette wall -o wall/pixel.png --smoothing 0
    (cd run && QT_QPA_PLATFORM=offscreen vignetteCalib_headless ../wall/)
    python3 xtask/peers/vignette_vs_2016.py wall wall/m.png wall/m_raw.png wall/pixel.png \
        run/vignetteCalibResult/vignette.png run/vignetteCalibResult/vignetteSmoothed.png \
        --through-2016-kernel wall/pixel.png
"""
import os
import sys

import cv2
import numpy as np

# what the 2016 tool's read-bilinearly-then-splat-bilinearly does to per-pixel noise
KERNEL_2016 = np.array([1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0])


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
    err = np.zeros_like(truth)
    err[valid] = e
    inner = np.zeros_like(valid)
    inner[3:-3, 3:-3] = True
    both = valid & inner
    hp = err - cv2.GaussianBlur(err, (0, 0), 4)
    pairs = both[:, :-1] & both[:, 1:]
    corr = (hp[:, :-1] * hp[:, 1:])[pairs].mean() / (hp[both] ** 2).mean()
    return 100 * np.sqrt(np.mean(e * e)), 100 * np.percentile(np.abs(e), 99), valid.mean(), corr


def main():
    args = sys.argv[1:]
    if len(args) < 2:
        sys.exit(__doc__)
    plain, filtered = args[1:], []
    if "--through-2016-kernel" in plain:
        i = plain.index("--through-2016-kernel")
        plain, filtered = plain[:i], plain[i + 1:]
    truth = load(os.path.join(args[0], "truth_vignette.png"))
    print(f"{'map':<72} {'rms %':>8} {'p99 %':>8} {'valid %':>8} {'nbr corr':>8}")
    maps = [(p, load(p)) for p in plain]
    for p in filtered:
        m = load(p)
        k = cv2.sepFilter2D(m, -1, KERNEL_2016, KERNEL_2016, borderType=cv2.BORDER_REPLICATE)
        maps.append((f"{p} through the 2016 kernel", np.where(m > 0, k, 0.0)))
    for name, m in maps:
        rms, p99, frac, corr = score(m, truth)
        print(f"{name:<72} {rms:8.3f} {p99:8.3f} {100 * frac:8.2f} {corr:8.2f}")


if __name__ == "__main__":
    main()
