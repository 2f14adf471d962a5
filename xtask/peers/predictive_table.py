#!/usr/bin/env python3
"""The table that the least-squares merge of bracket_scores.py rewards, and how far it is from
a camera's true inverse response.

The `ls` score merges each pixel's irradiance as B = sum t U(I) / sum t^2. For that merge the
best value of U at a code k is not the camera's inverse response but the mean exposure times
irradiance of the observations that read k, E[t B | I = k] (a regression on the code, which
noise pulls away from U). This script builds that table from a fitted one: every observation
of code k in a training frame gets t times the merge of the pixel's *other* training frames
through the fitted table, and U(k) moves to the mean of those values, shrunk towards the
fitted value with a prior weight of --kappa observations; the result is made increasing.

Two uses:

    # real brackets: the ls and ml scores of monovo's tables and of the predictive tables made
    # from them, over the best OpenCV method (tables from bracket_scores.py --json)
    venv/bin/python xtask/peers/predictive_table.py brackets SETS... --scores scores.json

    # synthetic sweeps (monovo synth sweep, then monovo calib response -o DIR/p.txt): the
    # largest error of the fitted table and of the predictive one against truth_pcalib.txt
    venv/bin/python xtask/peers/predictive_table.py sweeps DIR... [--bound 0.5]
"""
import argparse
import os
import sys
import zipfile

import cv2
import numpy as np

from bracket_breakdown import tables_of
from bracket_scores import fold_errors, groups, load_set

OPENCV = ["debevec", "robertson"]


def predictive(frames, times, train, u, kappa):
    """The predictive table made from `u` on the training frames."""
    stack = np.stack([frames[i] for i in train]).astype(np.int64)
    t = np.array([times[i] for i in train], np.float64)[:, None, None]
    ok = ((stack >= 1) & (stack <= 254)).astype(np.float64)
    uv = u[stack]
    num = (ok * t * uv).sum(0)
    den = (ok * t * t).sum(0)
    s = np.zeros(256)
    c = np.zeros(256)
    for k in range(len(train)):
        nk = num - ok[k] * t[k] * uv[k]
        dk = den - ok[k] * t[k] ** 2
        live = (ok[k] > 0) & (dk > 0)
        s += np.bincount(stack[k][live], t[k, 0, 0] * nk[live] / dk[live], 256)
        c += np.bincount(stack[k][live], minlength=256)
    out = (s + kappa * u) / (c + kappa)
    for k in range(1, 256):
        out[k] = max(out[k], out[k - 1] + 1e-9 * max(abs(out[k - 1]), 1.0))
    return out


def scores(frames, times, folds, per_fold):
    acc = np.zeros(5)
    for (_, test), u in zip(folds, per_fold):
        train = [i for i in range(len(frames)) if i not in test]
        acc += fold_errors(frames, times, train, test, np.array(u))
    return np.sqrt(acc[0] / acc[1]), np.sqrt(acc[4] / acc[1])


def brackets(args):
    tables = tables_of(args.scores)
    print(f"{'set':<28} {'ls fitted':>10} {'ls pred.':>10} {'ml fitted':>10} {'ml pred.':>10}"
          "   (over the best OpenCV method)")
    for folder in args.dirs:
        name = os.path.basename(os.path.normpath(folder))
        t = tables.get(name, {})
        if "monovo" not in t or not all(m in t for m in OPENCV):
            raise SystemExit(f"{folder}: monovo's and OpenCV's tables are needed in the scores")
        frames, times = load_set(folder)
        folds = groups(times)
        pred = []
        for (_, test), u in zip(folds, t["monovo"]):
            train = [i for i in range(len(frames)) if i not in test]
            pred.append(predictive(frames, times, train, np.array(u), args.kappa))
        best = [min(s) for s in zip(*(scores(frames, times, folds, t[m]) for m in OPENCV))]
        fit = scores(frames, times, folds, t["monovo"])
        new = scores(frames, times, folds, pred)
        print(f"{name:<28} {fit[0] / best[0]:10.3f} {new[0] / best[0]:10.3f} "
              f"{fit[1] / best[1]:10.3f} {new[1] / best[1]:10.3f}")
        sys.stdout.flush()


def read_sweep(folder, step):
    with zipfile.ZipFile(os.path.join(folder, "images.zip")) as z:
        frames = [cv2.imdecode(np.frombuffer(z.read(n), np.uint8),
                               cv2.IMREAD_GRAYSCALE)[::step, ::step]
                  for n in sorted(z.namelist())]
    times = []
    with open(os.path.join(folder, "times.txt")) as fh:
        for line in fh:
            c = line.split()
            if len(c) >= 3 and not line.startswith("#"):
                times.append(float(c[2]))
    return frames, times


def sweeps(args):
    print(f"{'sweep':<44} {'fitted max':>11} {'predictive max':>15} {'at':>4}  (grey values)")
    for folder in args.dirs:
        frames, times = read_sweep(folder, args.step)
        u = np.loadtxt(os.path.join(folder, args.table))
        truth = np.loadtxt(os.path.join(folder, "truth_pcalib.txt"))
        p = predictive(frames, times, list(range(len(frames))), u, args.kappa)
        if args.bound is not None:
            # the shift limited to BOUND standard errors (the fit's NAME_std.txt)
            std = np.loadtxt(os.path.join(folder, args.table[:-4] + "_std.txt"))
            p = u + np.clip(p - u, -args.bound * std, args.bound * std)
            p = np.maximum.accumulate(p)
        # both in the truth's gauge (U(255) the same)
        e0 = np.abs(u * truth[255] / u[255] - truth)
        e1 = np.abs(p * truth[255] / p[255] - truth)
        print(f"{os.path.basename(os.path.normpath(folder)):<44} {e0.max():11.3f} "
              f"{e1.max():15.3f} {int(e1.argmax()):4d}")
        sys.stdout.flush()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=["brackets", "sweeps"])
    ap.add_argument("dirs", nargs="+")
    ap.add_argument("--scores", nargs="+", help="bracket_scores.py JSON files with tables")
    ap.add_argument("--kappa", type=float, default=3000.0,
                    help="prior weight of the fitted value, in observations (default 3000)")
    ap.add_argument("--table", default="p.txt", help="the fitted table in each sweep folder")
    ap.add_argument("--bound", type=float, metavar="C",
                    help="sweeps: move each U(k) by at most C of its standard errors")
    ap.add_argument("--step", type=int, default=2, help="use every STEP-th pixel of a sweep")
    args = ap.parse_args()
    if args.what == "brackets" and not args.scores:
        raise SystemExit("brackets: --scores is needed")
    (brackets if args.what == "brackets" else sweeps)(args)


if __name__ == "__main__":
    main()
