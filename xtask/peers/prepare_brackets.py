#!/usr/bin/env python3
"""Makes the small grey fixtures of tests/fixtures/brackets/ from real exposure brackets.

Input: a folder with the original images and times.txt (`index timestamp_s
exposure_ms`, one line per image, in the order of `indexed/NNNNN.ext` or of the
file names listed in files.txt). Output: OUT/images/NNNNN.png (8-bit grey),
OUT/times.txt, and the SOURCE.txt of the input copied beside them.

Grey: the luma Y' = 0.299 R' + 0.587 G' + 0.114 B' (ITU-R BT.601) as OpenCV's
IMREAD_GRAYSCALE gives it: for JPEG the decoder's own Y channel, for PNG the
weighted sum rounded. Size: every f-th pixel in each direction, from (f/2, f/2),
with the smallest integer f that makes the longer side at most --max-side:
decimation without averaging keeps each pixel a pixel of the camera (an average of
pixels is not the response of an average irradiance).

    python3 xtask/peers/prepare_brackets.py SRC OUT --max-side 256
"""
import argparse
import os
import shutil
import sys

import cv2


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("src")
    ap.add_argument("out")
    ap.add_argument("--max-side", type=int, default=256)
    args = ap.parse_args()
    indexed = os.path.join(args.src, "indexed")
    names = sorted(os.listdir(indexed))
    times = [l.split() for l in open(os.path.join(args.src, "times.txt")) if l.strip()]
    if len(times) != len(names):
        sys.exit(f"{args.src}: {len(names)} images, {len(times)} lines in times.txt")
    os.makedirs(os.path.join(args.out, "images"), exist_ok=True)
    lines = []
    for i, (name, cols) in enumerate(zip(names, times)):
        img = cv2.imread(os.path.join(indexed, name), cv2.IMREAD_GRAYSCALE)
        if img is None:
            sys.exit(f"{name}: does not decode")
        h, w = img.shape
        f = max(1, -(-max(w, h) // args.max_side))
        small = img[f // 2::f, f // 2::f]
        cv2.imwrite(os.path.join(args.out, "images", f"{i:05d}.png"), small)
        lines.append(f"{i:05d} {i}.000000 {float(cols[2]):.6f}\n")
    with open(os.path.join(args.out, "times.txt"), "w") as fh:
        fh.writelines(lines)
    src = os.path.join(args.src, "SOURCE.txt")
    if os.path.exists(src):
        shutil.copy(src, os.path.join(args.out, "SOURCE.txt"))
    print(f"{args.out}: {len(names)} frames {small.shape[1]}x{small.shape[0]} (every {f}th pixel)")


if __name__ == "__main__":
    main()
