#!/usr/bin/env python3
"""The peer of `monovo rectify` in OpenCV: a sequence's images.zip decoded with cv2.imdecode
(libjpeg-turbo), remapped with cv2.remap (bilinear, from the FOV camera of camera.txt to the
pinhole of its line 3, `crop` only) and written as PNG frames with cv2.imwrite (OpenCV's
default PNG settings), on a pool of threads (OpenCV releases the GIL). `--decode-only` stops
after imdecode: the throughput every other figure is compared with.

    pip install opencv-python-headless numpy
    python3 xtask/peers/opencv_rectify.py SEQUENCE OUTDIR [--threads 2] [--decode-only]

Prints one JSON object: frames, seconds, fps. The map follows DESIGN.md (FOV model, relative
values, pixel centres at integers; the `crop` output camera in closed form), written here from
the formulas, not from any tool.
"""
import argparse
import json
import math
import os
import sys
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np


def read_camera(path):
    lines = open(path, encoding="utf-8-sig").read().splitlines()
    first = lines[0].split()
    if first[0].isalpha():
        if first[0] != "FOV":
            sys.exit(f"{path}: line 1: only the FOV model here, found {first[0]}")
        first = first[1:]
    fx, fy, cx, cy, omega = map(float, first[:5])
    w, h = map(int, lines[1].split()[:2])
    if lines[2].strip() != "crop":
        sys.exit(f"{path}: line 3: only `crop` here, found `{lines[2].strip()}`")
    ow, oh = map(int, lines[3].split()[:2])
    if cx < 1 and cy < 1:
        fx, fy, cx, cy = fx * w, fy * h, cx * w - 0.5, cy * h - 0.5
    return (fx, fy, cx, cy, omega), (w, h), (ow, oh)


def fov_map(cam, size, out):
    fx, fy, cx, cy, omega = cam
    w, h = size
    ow, oh = out

    def undistort(r):  # distorted radius -> undistorted (FOV model)
        return math.tan(r * omega) / (2.0 * math.tan(omega / 2.0))

    # crop: the axis extents of the input, undistorted, scaled to the output size (DESIGN.md,
    # the reference tools' closed form)
    l, r, t, b = cx / fx, (w - 1 - cx) / fx, cy / fy, (h - 1 - cy) / fy
    tl, tr, tt, tb = undistort(l), undistort(r), undistort(t), undistort(b)
    kfx = fx * (l + r) / (tl + tr) * ow / w
    kfy = fy * (t + b) / (tt + tb) * oh / h
    kcx, kcy = tl * kfx, tt * kfy
    u, v = np.meshgrid(np.arange(ow, dtype=np.float64), np.arange(oh, dtype=np.float64))
    x, y = (u - kcx) / kfx, (v - kcy) / kfy
    r = np.sqrt(x * x + y * y)
    factor = np.where(
        r > 1e-12,
        np.arctan(2.0 * r * math.tan(omega / 2.0)) / (omega * np.maximum(r, 1e-12)),
        2.0 * math.tan(omega / 2.0) / omega,
    )
    mx = (fx * x * factor + cx).astype(np.float32)
    my = (fy * y * factor + cy).astype(np.float32)
    return mx, my


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("outdir")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--decode-only", action="store_true")
    a = ap.parse_args()
    cv2.setNumThreads(1)  # the frames are the parallel unit, as in monovo
    cam, size, out = read_camera(os.path.join(a.sequence, "camera.txt"))
    t0 = time.perf_counter()
    mx, my = fov_map(cam, size, out)
    z = zipfile.ZipFile(os.path.join(a.sequence, "images.zip"))
    names = sorted(n for n in z.namelist() if n.lower().endswith((".jpg", ".jpeg", ".png")))
    os.makedirs(a.outdir, exist_ok=True)

    def one(k):
        # zipfile objects are not thread safe: one read per frame under the GIL
        data = np.frombuffer(z.read(names[k]), np.uint8)
        img = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
        if img is None or img.shape != (size[1], size[0]):
            raise SystemExit(f"{names[k]}: cannot decode, or not {size[0]}x{size[1]}")
        if a.decode_only:
            return
        rect = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        cv2.imwrite(os.path.join(a.outdir, f"{k:05d}.png"), rect)

    with ThreadPoolExecutor(a.threads) as pool:
        list(pool.map(one, range(len(names))))
    seconds = time.perf_counter() - t0
    print(json.dumps({"frames": len(names), "seconds": seconds, "fps": len(names) / seconds,
                      "decode_only": a.decode_only, "threads": a.threads}))


if __name__ == "__main__":
    main()
