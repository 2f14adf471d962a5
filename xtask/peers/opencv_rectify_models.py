#!/usr/bin/env python3
"""`monovo rectify` against OpenCV's remap through each real model: the first frame of a
sequence folder rectified by monovo to an explicit pinhole is compared with cv2.remap
(bilinear, border 0) of the raw frame through a map made by OpenCV's own undistortion
(cv2.initUndistortRectifyMap for RadTan, cv2.fisheye for EquiDistant / Kannala-Brandt,
cv2.omnidir for the omni model) or, for Double Sphere and EUCM which OpenCV lacks, by the
paper's formulas written here in numpy.

    python3 -m venv /tmp/peers && /tmp/peers/bin/pip install opencv-contrib-python-headless numpy pyyaml
    /tmp/peers/bin/python xtask/peers/opencv_rectify_models.py RAW_FRAME.png RECTIFIED.png \\
        --calib FILE --cam N --pinhole "fx fy cx cy" --size WxH

RAW_FRAME is the dataset's frame, RECTIFIED monovo's output for it (8 or 16 bits). Prints one
JSON object: the model, the number of compared pixels (valid in both), the mean absolute
difference and the share within 2 grey levels (in 8-bit units).
"""
import argparse
import json
import math

import cv2
import numpy as np
import yaml


def load(calib, cam):
    text = open(calib, encoding="utf-8").read()
    if text.lstrip().startswith("{"):
        c = json.loads(text)["value0"]["intrinsics"][cam]
        i = c["intrinsics"]
        k = np.array([[i["fx"], 0, i["cx"]], [0, i["fy"], i["cy"]], [0, 0, 1.0]])
        t = c["camera_type"]
        if t == "ds":
            return "DoubleSphere", k, (i["xi"], i["alpha"])
        if t == "eucm":
            return "EUCM", k, (i["alpha"], i["beta"])
        if t == "kb4":
            return "KannalaBrandt", k, np.array([i["k1"], i["k2"], i["k3"], i["k4"]])
        raise SystemExit(f"camera_type {t}")
    y = yaml.safe_load(text)
    if "cam0" in y:
        c = y[f"cam{cam}"]
        intr, model, dist = c["intrinsics"], c["camera_model"], c.get("distortion_model", "none")
        coeffs = np.array(c.get("distortion_coeffs", []), dtype=float)
    else:
        intr, model, dist = y["intrinsics"], y.get("camera_model", "pinhole"), y["distortion_model"]
        coeffs = np.array(y["distortion_coefficients"], dtype=float)
    if model == "omni":
        xi, fu, fv, pu, pv = intr
        k = np.array([[fu, 0, pu], [0, fv, pv], [0, 0, 1.0]])
        return "Omni", k, (xi, coeffs if len(coeffs) else np.zeros(4))
    fu, fv, pu, pv = intr
    k = np.array([[fu, 0, pu], [0, fv, pv], [0, 0, 1.0]])
    if dist in ("radtan", "radial-tangential"):
        return "RadTan", k, coeffs
    if dist in ("equidistant", "equi"):
        return "EquiDistant", k, coeffs
    raise SystemExit(f"{model} {dist}")


def rays(p, w, h):
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    return (u - p[2]) / p[0], (v - p[3]) / p[1]


def sphere_map(model, k, params, p, w, h):
    """Double Sphere (Usenko et al. 2018, eq. 40-43) and EUCM (eq. 27-28) projections."""
    x, y = rays(p, w, h)
    z = np.ones_like(x)
    if model == "DoubleSphere":
        xi, alpha = params
        d1 = np.sqrt(x * x + y * y + z * z)
        kk = xi * d1 + z
        d2 = np.sqrt(x * x + y * y + kk * kk)
        den = alpha * d2 + (1 - alpha) * kk
    else:
        alpha, beta = params
        rho = np.sqrt(beta * (x * x + y * y) + z * z)
        den = alpha * rho + (1 - alpha) * z
    mx = (k[0, 0] * x / den + k[0, 2]).astype(np.float32)
    my = (k[1, 1] * y / den + k[1, 2]).astype(np.float32)
    return mx, my


def main():
    a = argparse.ArgumentParser()
    a.add_argument("raw")
    a.add_argument("rectified")
    a.add_argument("--calib", required=True)
    a.add_argument("--cam", type=int, default=0)
    a.add_argument("--pinhole", required=True, help="relative fx fy cx cy, as monovo's --pinhole")
    a.add_argument("--size", required=True)
    args = a.parse_args()
    w, h = (int(s) for s in args.size.split("x"))
    r = [float(s) for s in args.pinhole.split()[:4]]
    p = [r[0] * w, r[1] * h, r[2] * w - 0.5, r[3] * h - 0.5]
    P = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]])
    model, k, params = load(args.calib, args.cam)
    if model == "RadTan":
        mx, my = cv2.initUndistortRectifyMap(k, params, None, P, (w, h), cv2.CV_32FC1)
    elif model in ("EquiDistant", "KannalaBrandt"):
        mx, my = cv2.fisheye.initUndistortRectifyMap(k, params, np.eye(3), P, (w, h), cv2.CV_32FC1)
    elif model == "Omni":
        xi, d = params
        mx, my = cv2.omnidir.initUndistortRectifyMap(k, d.reshape(1, 4), np.array([[xi]]), np.eye(3), P, (w, h), cv2.CV_32FC1, cv2.omnidir.RECTIFY_PERSPECTIVE)
    else:
        mx, my = sphere_map(model, k, params, p, w, h)
    raw = cv2.imread(args.raw, cv2.IMREAD_UNCHANGED).astype(np.float32)
    ours = cv2.imread(args.rectified, cv2.IMREAD_UNCHANGED).astype(np.float64)
    scale = 257.0 if ours.dtype == np.uint16 or ours.max() > 255 else 1.0
    theirs = cv2.remap(raw, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    rh, rw = raw.shape[:2]
    inside = (mx >= 0) & (my >= 0) & (mx <= rw - 1) & (my <= rh - 1)
    valid = inside & (ours > 0)
    d = np.abs(ours[valid] / scale - theirs[valid] / scale)
    print(json.dumps({
        "model": model,
        "opencv": cv2.__version__,
        "pixels": int(valid.sum()),
        "inside_but_zero_in_monovo": int((inside & (ours == 0)).sum()),
        "mean_abs_diff": float(d.mean()),
        "within_2": float((d <= 2).mean()),
        "max_abs_diff": float(d.max()),
    }))


if __name__ == "__main__":
    main()
