#!/usr/bin/env python3
"""Leave-one-exposure-out scores of response calibrations on real exposure brackets.

For every bracket folder (images/ with 8-bit grey PNGs, times.txt `id timestamp_s
exposure_ms`) and every distinct exposure e_j: each method calibrates the inverse
response U on the frames of the other exposures; the frames at e_j are then
predicted from the others through that U and compared with what the camera
recorded. No truth is needed: a response that explains the data predicts the
left-out exposure well.

Methods:
    monovo      `monovo calib response` (the release build; MONOVO or --monovo)
    debevec     OpenCV's CalibrateDebevec (samples=70, lambda=10, random=False)
    robertson   OpenCV's CalibrateRobertson (max_iter=30, threshold=0.01), on
                GRAY2BGR frames (its tables are hard-wired to 3 channels), channel 0
    tum2016     the authors' responseCalib (github.com/tum-vision/mono_dataset_code),
                when --tum2016 BINARY is given (see docs/reference-tools.md)

OpenCV's value at 255 averages over saturated pixels; as in opencv_response.py it
is replaced by 2 U(254) - U(253). A method whose table is not finite, or that
fails, scores null on that fold (and the set's score is null).

Scores, per set, pooled over all folds, on the pixels every method scores (the
left-out value in 1..254 and at least one other frame with a value in 1..254):
    ls    B = sum t U(I) / sum t^2 over the other frames' values in 1..254 (the
          paper's least-squares irradiance); RMS of I_j - G(t_j B) in grey levels
    tri   the same with Debevec's triangle weights h(z) = min(z, 255 - z): B =
          sum h t U / sum h t^2, and the squared errors weighted by h(I_j)
    ml    as ls, but B by least squares in grey levels, min sum (I - G(t B))^2 over
          the same values (Gauss-Newton from the ls B): every table predicts through the
          merge that suits it best, so the score measures the table and not the noise
          that the ls merge carries from the steep top of U into B
G = U^-1 is the piecewise-linear inverse of the table (made non-decreasing first),
clamped to 0..255.

Run (the peers' numbers committed in tests/fixtures/brackets/peer_scores.json):
    python3 -m venv venv && venv/bin/pip install opencv-python-headless numpy
    venv/bin/python xtask/peers/bracket_scores.py tests/fixtures/brackets/*/ \
        --no-monovo [--tum2016 PATH/responseCalib] --no-tables \
        --json tests/fixtures/brackets/peer_scores.json
"""
import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile

import cv2
import numpy as np

from opencv_response import load_sweep, read_exposures_ms



def load_set(folder):
    """(grey frames, exposures in ms) of a bracket folder, read as opencv_response.py reads
    a sweep."""
    frames, _ = load_sweep(folder)
    return frames, read_exposures_ms(folder, len(frames))


def groups(times):
    """Distinct exposures (relative tolerance 1e-6) and the frame indices of each."""
    order = np.argsort(times, kind="stable")
    out = []
    for i in order:
        if out and abs(times[i] / out[-1][0] - 1.0) < 1e-6:
            out[-1][1].append(int(i))
        else:
            out.append((float(times[i]), [int(i)]))
    return out


def finite_table(u):
    u = np.asarray(u, np.float64).reshape(256, -1)[:, 0].copy()
    ok = np.isfinite(u)
    if ok.sum() < 3:
        return None
    if not ok.all():
        k = np.arange(256)
        u[~ok] = np.interp(k[~ok], k[ok], u[ok])
    return u


def opencv_table(table):
    u = finite_table(table)
    if u is None:
        return None
    u[255] = 2 * u[254] - u[253]
    return u


def write_subset(folder, frames, times, keep, camera=True):
    os.makedirs(os.path.join(folder, "images"))
    with open(os.path.join(folder, "times.txt"), "w") as fh:
        for j, i in enumerate(keep):
            cv2.imwrite(os.path.join(folder, "images", f"{j:05d}.png"), frames[i])
            fh.write(f"{j} {j} {float(times[i])!r}\n")
    if camera:
        h, w = frames[0].shape
        # a camera.txt for the authors' reader (it builds an undistorter; the
        # response calibration reads the raw frames)
        with open(os.path.join(folder, "camera.txt"), "w") as fh:
            fh.write("0.5 0.5 0.5 0.5 0.9\n")
            fh.write(f"{w} {h}\ncrop\n{w} {h}\n")


def run_monovo(binary, folder, work, extra=""):
    out = os.path.join(work, "monovo_pcalib.txt")
    r = subprocess.run([binary, "calib", "response", folder, "-o", out, "--force", "--json"]
                       + extra.split(), capture_output=True, text=True)
    if r.returncode != 0:
        return None, r.stderr.strip().splitlines()[-1:] if r.stderr else ["failed"]
    return np.array(open(out).read().split(), np.float64), None


def run_tum2016(binary, folder, work):
    cwd = os.path.join(work, "tum2016")
    os.makedirs(cwd)
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    try:
        r = subprocess.run([binary, folder.rstrip("/") + "/"], cwd=cwd, capture_output=True,
                           text=True, env=env, timeout=600)
    except subprocess.TimeoutExpired:
        return None, ["timeout"]
    path = os.path.join(cwd, "photoCalibResult", "pcalib.txt")
    if r.returncode != 0 or not os.path.exists(path):
        return None, [f"exit {r.returncode}"]
    raw = np.array(open(path).read().split(), np.float64)
    if raw.size != 256 or not np.isfinite(raw).all():
        return None, ["non-finite table"]
    return raw, None


def inverse(u, e):
    """G(e): the fractional code where the (non-decreasing) table reaches e."""
    m = np.maximum.accumulate(u)
    return np.clip(np.interp(e, m, np.arange(256, dtype=np.float64)), 0.0, 255.0)


def grey_merge(stack, t, ok, u, b):
    """B of every pixel by least squares in grey levels, min sum ok (I - G(t B))^2, by
    Gauss-Newton steps from `b` (each kept above a tenth of the previous B)."""
    m = np.maximum.accumulate(u)
    codes = np.arange(256, dtype=np.float64)
    for _ in range(GREY_MERGE_STEPS):
        g = np.clip(np.interp(t * b[None], m, codes), 0.0, 255.0)
        j = np.clip(np.floor(g).astype(np.int64), 0, 254)
        du = m[j + 1] - m[j]
        live = (g > 0.0) & (g < 255.0) & (du > 0.0)
        d = np.where(live, t / np.where(du > 0.0, du, 1.0), 0.0) * ok
        jr = (d * (stack - g)).sum(0)
        jj = (d * d).sum(0)
        step = np.where(jj > 0.0, jr / np.where(jj > 0.0, jj, 1.0), 0.0)
        b = np.maximum(b + step, 0.1 * b)
    return b


GREY_MERGE_STEPS = 8


def fold_residuals(frames, times, train, test, u):
    """The residuals of one fold on its scored pixels, one array per score, in the order of
    the held-out frames: (r_ls, r_tri, h, r_ml, top), where h are the triangle weights of the
    recorded values and top is each pixel's value in its longest training frame with a value
    in 1..254 (the value that dominates the least-squares merge)."""
    stack = np.stack([frames[i] for i in train]).astype(np.int32)
    t = np.array([times[i] for i in train])[:, None, None]
    ok = (stack >= 1) & (stack <= 254)
    uv = u[stack]
    h = np.minimum(stack, 255 - stack).astype(np.float64) * ok
    okf = ok.astype(np.float64)
    num_ls = (okf * t * uv).sum(0)
    den_ls = (okf * t * t).sum(0)
    num_tri = (h * t * uv).sum(0)
    den_tri = (h * t * t).sum(0)
    has = ok.any(0)
    top = np.take_along_axis(stack, np.where(ok, t, -1.0).argmax(0)[None], 0)[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        b_ml = grey_merge(stack.astype(np.float64), t, okf, u,
                          np.where(has, num_ls / den_ls, 0.0))
    out = [[], [], [], [], []]
    for j in test:
        obs = frames[j].astype(np.float64)
        mask = has & (frames[j] >= 1) & (frames[j] <= 254)
        o = obs[mask]
        out[0].append(o - inverse(u, times[j] * num_ls[mask] / den_ls[mask]))
        out[1].append(o - inverse(u, times[j] * num_tri[mask] / den_tri[mask]))
        out[2].append(np.minimum(o, 255 - o))
        out[3].append(o - inverse(u, times[j] * b_ml[mask]))
        out[4].append(top[mask])
    return [np.concatenate(x) for x in out]


def fold_errors(frames, times, train, test, u):
    """(sse_ls, n_ls, sse_tri, wsum_tri, sse_ml) of one fold."""
    r_ls, r_tri, w, r_ml, _ = fold_residuals(frames, times, train, test, u)
    return [float(r_ls @ r_ls), int(r_ls.size), float((w * r_tri) @ r_tri), float(w.sum()),
            float(r_ml @ r_ml)]


def peers(us, frames, times, train, sub, work, args):
    """The peers' tables on the training frames."""
    grey = [frames[i] for i in train]
    tt = np.array([times[i] / 1000.0 for i in train], np.float32)
    deb = cv2.createCalibrateDebevec(samples=70, lambda_=10.0, random=False)
    us["debevec"] = (opencv_table(deb.process(grey, tt)), None)
    rob = cv2.createCalibrateRobertson(max_iter=30, threshold=0.01)
    bgr = [cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) for f in grey]
    us["robertson"] = (opencv_table(rob.process(bgr, tt)), None)
    if args.tum2016:
        us["tum2016"] = run_tum2016(args.tum2016, sub, work)


def score_set(folder, args):
    frames, times = load_set(folder)
    gs = groups(times)
    methods = (["monovo"] if args.monovo else []) + (
        [] if args.no_peers else ["debevec", "robertson"] + (["tum2016"] if args.tum2016 else []))
    acc = {m: [0.0, 0, 0.0, 0.0, 0.0] for m in methods}
    failed = {m: [] for m in methods}
    tables = {m: [] for m in methods}
    for e, test in gs:
        train = [i for i in range(len(frames)) if i not in test]
        with tempfile.TemporaryDirectory() as work:
            sub = os.path.join(work, "set")
            write_subset(sub, frames, times, train)
            us = {}
            if args.monovo:
                us["monovo"] = run_monovo(args.monovo, sub, work, args.monovo_args)
            if args.no_peers:
                pass
            else:
                peers(us, frames, times, train, sub, work, args)
        for m in methods:

            u, why = us.get(m, (None, ["not run"]))
            if u is None:
                failed[m].append({"exposure_ms": e, "why": why or ["non-finite table"]})
                tables[m].append(None)
                continue
            tables[m].append([float(x) for x in u])
            r = fold_errors(frames, times, train, test, u)
            for k in range(5):
                acc[m][k] += r[k]
    h, w = frames[0].shape
    res = {"frames": len(frames), "exposures": len(gs), "size": [w, h], "methods": {}}
    for m in methods:
        a = acc[m]
        ok = not failed[m]
        res["methods"][m] = {
            "ls": float(np.sqrt(a[0] / a[1])) if ok and a[1] else None,
            "tri": float(np.sqrt(a[2] / a[3])) if ok and a[3] else None,
            "ml": float(np.sqrt(a[4] / a[1])) if ok and a[1] else None,
            "pixels": a[1],
            "failed_folds": failed[m],
            "tables": tables[m],
        }
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sets", nargs="+")
    ap.add_argument("--monovo", default=os.environ.get("MONOVO"))
    ap.add_argument("--tum2016", default=os.environ.get("RESPONSECALIB"))
    ap.add_argument("--json", metavar="FILE", help="write the scores and tables here")
    ap.add_argument("--no-monovo", action="store_true", help="only the peers")
    ap.add_argument("--no-peers", action="store_true", help="only monovo")
    ap.add_argument("--monovo-args", default="", help="extra arguments of monovo calib response")
    ap.add_argument("--no-tables", action="store_true",
                    help="leave the fitted tables out of the JSON (scores only)")
    args = ap.parse_args()
    if args.no_monovo:
        args.monovo = None
    out = {
        "tool": "xtask/peers/bracket_scores.py",
        "opencv": cv2.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "tum2016": "tum-vision/mono_dataset_code responseCalib" if args.tum2016 else None,
        "sets": {},
    }
    print(f"{'set':<24} {'method':<10} {'ls':>8} {'tri':>8} {'ml':>8}  failed folds")
    for folder in args.sets:
        name = os.path.basename(os.path.normpath(folder))
        res = score_set(folder, args)
        if args.no_tables:
            for r in res["methods"].values():
                del r["tables"]
        out["sets"][name] = res
        for m, r in res["methods"].items():
            f = lambda v: "-" if v is None else f"{v:.3f}"
            print(f"{name:<24} {m:<10} {f(r['ls']):>8} {f(r['tri']):>8} {f(r['ml']):>8}"
                  f"  {len(r['failed_folds'])}")
        sys.stdout.flush()
    if args.json:
        tmp = args.json + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(out, fh, indent=1)
            fh.write("\n")
        shutil.move(tmp, args.json)


if __name__ == "__main__":
    main()
