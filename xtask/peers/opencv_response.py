#!/usr/bin/env python3
"""Peer comparison: OpenCV's response calibrations on a monovo exposure sweep.

Runs cv2.createCalibrateDebevec() and cv2.createCalibrateRobertson() on the grey
frames of a sweep folder written by `monovo synth sweep` (or any sequence folder
with images.zip / images/ and times.txt holding exposures) and scores the
recovered inverse response U against the folder's truth_pcalib.txt.

Run:
    pip install opencv-python-headless numpy
    python3 opencv_response.py SWEEP                     # table
    python3 opencv_response.py SWEEP --json              # one JSON object
    python3 opencv_response.py SWEEP --write-pcalib DIR  # also write U files
    python3 opencv_response.py SWEEP --compare-pcalib pcalib.txt   # score any U
    Defaults are OpenCV's: Debevec samples=70 lambda=10 random=False,
    Robertson max_iter=30 threshold=0.01 (--debevec-samples, --debevec-lambda,
    --robertson-iter, --robertson-threshold change them).

Input: images sorted by name (images.zip with flat or images/ entries, or an
images/ folder), decoded as 8-bit grey; times.txt lines `id timestamp_s
exposure_ms` (exposures converted to seconds, float32). truth_pcalib.txt is
one line of 256 numbers, the true U scaled to U(255) = 255.

How OpenCV's output becomes U(0..255): both methods return a 256x1 float32
table per channel proportional to the inverse response (Debevec: exp(g) with
g(128) ~ 0; Robertson: U with U(128) = 1).  Their value at 255 averages over
saturated pixels and is meaningless, so U(255) is replaced by the linear
extrapolation 2 U(254) - U(253), then U is scaled to U(255) = 255.  Codes that
never occur come back from Robertson as NaN (0 * 1/0); they are counted
(`nan_codes`) and filled by linear interpolation between the nearest finite
codes (constant beyond the ends) so the other metrics stay defined; if code
128 never occurs Robertson's table is all NaN and the metrics are null.

Metrics, over k = 0..254 against the truth U_true:
    max        max |U(k) - U_true(k)|   (grey levels; depends on the U(255) scale)
    shape_rms  sqrt(mean (s U(k) - U_true(k))^2), s = sum U U_true / sum U^2
               (the error of the curve's shape, free of the scale)
    max_250, shape_rms_250  the same over k = 0..250 with the best scale over
               0..250 (free of the top codes and of the U(255) normalisation:
               the kindest score for a method that fails only near saturation)
    increasing U strictly increasing over 0..255 (DSO rejects anything else)
    time_s     wall time of the OpenCV process() call alone

--compare-pcalib FILE scores a pcalib.txt as written (it is only rescaled to
U(255) = 255 if it is not already; no extrapolation), so monovo's own
U(255) counts.

Grey input: Debevec handles 1-channel images; Robertson does not (its
working tables are hard-wired to 3 channels and it corrupts the heap on
1-channel input in OpenCV 5.0.0), so Robertson gets GRAY2BGR frames and
channel 0 of the result is used.  --bgr gives Debevec BGR frames as well.
"""
import argparse
import json
import os
import sys
import time
import zipfile

import cv2
import numpy as np

IMAGE_EXT = (".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff")


def load_sweep(folder):
    """Return (list of HxW uint8 frames, float32 exposures in seconds)."""
    zpath = os.path.join(folder, "images.zip")
    frames = []
    if os.path.exists(zpath):
        with zipfile.ZipFile(zpath) as z:
            names = sorted((n for n in z.namelist() if n.lower().endswith(IMAGE_EXT)),
                           key=os.path.basename)
            for n in names:
                buf = np.frombuffer(z.read(n), np.uint8)
                frames.append(cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE))
    else:
        d = os.path.join(folder, "images")
        for n in sorted(f for f in os.listdir(d) if f.lower().endswith(IMAGE_EXT)):
            frames.append(cv2.imread(os.path.join(d, n), cv2.IMREAD_GRAYSCALE))
    if not frames or any(f is None for f in frames):
        sys.exit(f"{folder}: no images, or an image failed to decode")
    exposures_ms = read_exposures_ms(folder, len(frames))
    return frames, (exposures_ms / 1000.0).astype(np.float32)


def read_exposures_ms(folder, frames):
    """The exposure column of FOLDER/times.txt (ms, float64), one per frame."""
    exposures_ms = []
    with open(os.path.join(folder, "times.txt")) as fh:
        for lineno, line in enumerate(fh, 1):
            cols = line.split()
            if not cols or cols[0].startswith("#"):
                continue
            if len(cols) < 3:
                sys.exit(f"{folder}/times.txt:{lineno}: no exposure column")
            exposures_ms.append(float(cols[2]))
    if len(exposures_ms) != frames:
        sys.exit(f"{folder}: {frames} images but {len(exposures_ms)} exposures")
    return np.asarray(exposures_ms, np.float64)


def load_pcalib(path):
    u = np.array(open(path).read().split(), dtype=np.float64)
    if u.size != 256:
        sys.exit(f"{path}: {u.size} numbers, expected 256")
    return u


def fill_nan(u):
    """Linearly interpolate non-finite entries; return (filled copy, count)."""
    ok = np.isfinite(u)
    k = np.arange(u.size)
    out = u.copy()
    if ok.sum() < 3:  # nothing to interpolate from
        return np.full_like(u, np.nan), int((~ok).sum())
    if not ok.all():
        out[~ok] = np.interp(k[~ok], k[ok], u[ok])
    return out, int((~ok).sum())


def opencv_to_u(table):
    """OpenCV's 256x1xC table (channel 0) -> U(0..255) with U(255) = 255."""
    u = np.asarray(table, np.float64).reshape(256, -1)[:, 0]
    u, nan_codes = fill_nan(u)
    u[255] = 2 * u[254] - u[253]
    return u * (255.0 / u[255]), nan_codes


def score(u, u_true):
    """The metrics of the docstring, over k = 0..254."""
    a, t = u[:255], u_true[:255]
    if not np.isfinite(a).all():
        return {"max": None, "shape_rms": None, "scale": None, "increasing": False}
    s = float(a @ t / (a @ a))
    # the same without the top codes (251..254, where saturated pixels pull every
    # estimator) and without the U(255) normalisation: the best scale over 0..250
    a2, t2 = u[:251], u_true[:251]
    s2 = float(a2 @ t2 / (a2 @ a2))
    return {
        "max": float(np.max(np.abs(a - t))),
        "shape_rms": float(np.sqrt(np.mean((s * a - t) ** 2))),
        "scale": s,
        "max_250": float(np.max(np.abs(s2 * a2 - t2))),
        "shape_rms_250": float(np.sqrt(np.mean((s2 * a2 - t2) ** 2))),
        "increasing": bool(np.all(np.diff(u) > 0)),
    }


def run(calibrator, frames, times, u_true):
    t0 = time.perf_counter()
    table = calibrator.process(frames, times)
    elapsed = time.perf_counter() - t0
    u, nan_codes = opencv_to_u(table)
    res = score(u, u_true)
    raw_128 = float(np.reshape(table, (256, -1))[128, 0])  # OpenCV's anchor: ~1
    res.update(time_s=elapsed, nan_codes=nan_codes,
               raw_128=raw_128 if np.isfinite(raw_128) else None)
    return res, u


def write_u(path, u):
    if not np.isfinite(u).all():
        print(f"not writing {path}: no finite table", file=sys.stderr)
        return
    with open(path, "w") as fh:
        fh.write(" ".join(repr(float(x)) for x in u) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sweep")
    ap.add_argument("--debevec-samples", type=int, default=70)
    ap.add_argument("--debevec-lambda", type=float, default=10.0)
    ap.add_argument("--robertson-iter", type=int, default=30)
    ap.add_argument("--robertson-threshold", type=float, default=0.01)
    ap.add_argument("--bgr", action="store_true", help="give Debevec BGR frames too")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--write-pcalib", metavar="DIR")
    ap.add_argument("--compare-pcalib", metavar="FILE", action="append", default=[],
                    help="also score this pcalib.txt (repeatable)")
    ap.add_argument("--skip-opencv", action="store_true",
                    help="only score the --compare-pcalib files")
    args = ap.parse_args()

    u_true = load_pcalib(os.path.join(args.sweep, "truth_pcalib.txt"))
    out = {}
    if not args.skip_opencv:
        grey, times = load_sweep(args.sweep)
        bgr = [cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) for f in grey]
        h, w = grey[0].shape
        out.update(frames=len(grey), size=[w, h], opencv=cv2.__version__)
        deb = cv2.createCalibrateDebevec(samples=args.debevec_samples,
                                         lambda_=args.debevec_lambda, random=False)
        out["debevec"], u_deb = run(deb, bgr if args.bgr else grey, times, u_true)
        rob = cv2.createCalibrateRobertson(max_iter=args.robertson_iter,
                                           threshold=args.robertson_threshold)
        out["robertson"], u_rob = run(rob, bgr, times, u_true)
        if args.write_pcalib:
            os.makedirs(args.write_pcalib, exist_ok=True)
            write_u(os.path.join(args.write_pcalib, "debevec_pcalib.txt"), u_deb)
            write_u(os.path.join(args.write_pcalib, "robertson_pcalib.txt"), u_rob)
    for path in args.compare_pcalib:
        u = load_pcalib(path)
        u, nan_codes = fill_nan(u)
        res = score(u * (255.0 / u[255]), u_true)
        res["nan_codes"] = nan_codes
        out[path] = res

    if args.json:
        print(json.dumps(out))
        return
    if "frames" in out:
        print(f"{args.sweep}: {out['frames']} frames {out['size'][0]}x{out['size'][1]}, "
              f"OpenCV {out['opencv']}")
    print(f"{'method':<28} {'max':>9} {'shape_rms':>10} {'increasing':>10} {'nan':>4} {'time_s':>8}")
    for key, r in out.items():
        if isinstance(r, dict):
            t = f"{r['time_s']:8.3f}" if "time_s" in r else f"{'-':>8}"
            m, rms = (f"{r[x]:.3f}" if r[x] is not None else "NaN" for x in ("max", "shape_rms"))
            print(f"{key:<28} {m:>9} {rms:>10} {str(r['increasing']):>10} {r['nan_codes']:>4} {t}")


if __name__ == "__main__":
    main()
