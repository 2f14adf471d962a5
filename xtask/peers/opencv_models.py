#!/usr/bin/env python3
"""The camera models of monovo against OpenCV's own implementations, through the real
calibration files of tests/fixtures/datasets: RadTan (cv2.projectPoints), EquiDistant and
Kannala-Brandt (cv2.fisheye.projectPoints) and the unified omni model with radial-tangential
distortion (cv2.omnidir.projectPoints, opencv-contrib). OpenCV has no Double Sphere or EUCM.

    python3 -m venv /tmp/peers && /tmp/peers/bin/pip install opencv-contrib-python-headless numpy pyyaml
    /tmp/peers/bin/python xtask/peers/opencv_models.py > tests/fixtures/datasets/peers/opencv_projections.json

Prints one JSON object: the versions used and, per camera, the 3D points and the pixels
OpenCV projects them to. camera-model's tests (tests/calibration.rs) project the same points
and compare. The calibration files are read here with PyYAML and json, independently of
monovo's parsers.
"""
import json
import math
import os
import sys

import cv2
import numpy as np
import yaml

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "fixtures", "datasets")


def points(max_deg):
    """Directions on rings up to max_deg from the axis, at two depths."""
    out = []
    for ring in range(0, 7):
        theta = math.radians(max_deg) * ring / 6
        for k in range(12 if ring else 1):
            phi = 2 * math.pi * k / 12 + 0.1 * ring
            d = 0.7 + 2.3 * ((ring + k) % 3)
            out.append([d * math.sin(theta) * math.cos(phi), d * math.sin(theta) * math.sin(phi), d * math.cos(theta)])
    return np.array(out, dtype=np.float64)


def k_matrix(fx, fy, cx, cy):
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)


def case(file, cam, model, pts, px):
    return {"file": file, "cam": cam, "model": model, "points": pts.tolist(), "pixels": px.reshape(-1, 2).tolist()}


def main():
    cases = []
    zero = np.zeros(3)
    # EuRoC sensor.yaml: pinhole + radial-tangential
    f = "calib/scratch_slam__mav0__cam0__sensor.yaml"
    s = yaml.safe_load(open(os.path.join(ROOT, f)))
    pts = points(45)
    px, _ = cv2.projectPoints(pts, zero, zero, k_matrix(*s["intrinsics"]), np.array(s["distortion_coefficients"]))
    cases.append(case(f, 0, "RadTan", pts, px))
    # Kalibr camchains: pinhole + equidistant
    for f in ["calib/dm-vio__tumvi_calib__camchain.yaml", "calib/kalibr__working_directory__camchain-imucam-camera_imu.yaml"]:
        chain = yaml.safe_load(open(os.path.join(ROOT, f)))
        for cam in sorted(k for k in chain if k.startswith("cam")):
            c = chain[cam]
            pts = points(85)
            px, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), zero, zero, k_matrix(*c["intrinsics"]), np.array(c["distortion_coeffs"]))
            cases.append(case(f, int(cam[3:]), "EquiDistant", pts, px))
    # Basalt kb4 (the same polynomial in the angle)
    f = "calib/basalt__t265_kb4_calib.json"
    b = json.load(open(os.path.join(ROOT, f)))["value0"]
    for cam, intr in enumerate(b["intrinsics"]):
        i = intr["intrinsics"]
        pts = points(85)
        px, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), zero, zero, k_matrix(i["fx"], i["fy"], i["cx"], i["cy"]), np.array([i["k1"], i["k2"], i["k3"], i["k4"]]))
        cases.append(case(f, cam, "KannalaBrandt", pts, px))
    # Kalibr omni-radtan (Mei's unified model): intrinsics [xi fu fv pu pv]
    f = "calib/kalibr-wiki__Yaml-formats__chain.yaml"
    chain = yaml.safe_load(open(os.path.join(ROOT, f)))
    for cam in sorted(k for k in chain if k.startswith("cam")):
        c = chain[cam]
        xi, fu, fv, pu, pv = c["intrinsics"]
        pts = points(50)
        px, _ = cv2.omnidir.projectPoints(pts.reshape(-1, 1, 3), zero.reshape(1, 3), zero.reshape(1, 3), k_matrix(fu, fv, pu, pv), xi, np.array(c["distortion_coeffs"]).reshape(1, 4))
        cases.append(case(f, int(cam[3:]), "Omni", pts, px))
    json.dump({
        "tool": "xtask/peers/opencv_models.py",
        "opencv": cv2.__version__,
        "numpy": np.__version__,
        "python": sys.version.split()[0],
        "cases": cases,
    }, sys.stdout, separators=(",", ":"))
    print()


if __name__ == "__main__":
    main()
