#!/usr/bin/env python3
"""The Python package against its peers on the same data:

1. 1000 evaluations (`monovo synth results`: 50 sequences, 2 methods, forwards and
   backwards, 5 runs each) by monovo.evaluate_many, by monovo.evaluate one at a time, and by
   the same loop-closure metrics written with evo's Python API (file_interface to read,
   geometry.umeyama_alignment for the three Sim(3) alignments, numpy for the rest), whose
   numbers are checked against monovo's first;
2. frame iteration from Python (raw, rectified to the camera.txt's pinhole, and
   photometrically corrected) against `monovo rectify`'s rate on the same sequence (300
   frames of 1280x1024 JPEG, `monovo synth sequence`).

    pip install . evo
    python3 xtask/peers/python_bench.py [--monovo target/release/monovo] [--rounds 3]

Each measurement alternates the contenders for `--rounds` rounds and reports every round;
prints one JSON object.
"""
import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import monovo


def sh(*args):
    subprocess.run([str(a) for a in args], check=True, capture_output=True)


# ---- the loop-closure metrics with evo's API --------------------------------------------------


def evo_evaluate(est_path, gt_path):
    """e_align, e_s, e_r, e_t, e_rmse of DESIGN.md's procedure, with evo reading the files and
    aligning (Umeyama with scale); None when the run fails."""
    from evo.core import geometry
    from evo.tools import file_interface

    est = file_interface.read_tum_trajectory_file(str(est_path))
    gt = file_interface.read_tum_trajectory_file(str(gt_path))
    if est.num_poses == 0:
        return None
    order = np.argsort(est.timestamps, kind="stable")
    t = est.timestamps[order]
    p = est.positions_xyz[order]
    if not (np.isfinite(t).all() and np.isfinite(p).all()):
        return None
    gt_t = gt.timestamps
    if abs(t[0] - gt_t[0]) > 1000.0:  # backwards runs with 2e9 - t stamps
        t = 2e9 - t[::-1]
        p = p[::-1]
    j = np.searchsorted(gt_t, t)
    j0 = np.clip(j - 1, 0, len(gt_t) - 1)
    j1 = np.clip(j, 0, len(gt_t) - 1)
    j = np.where(np.abs(gt_t[j0] - t) <= np.abs(gt_t[j1] - t), j0, j1)
    if (np.abs(gt_t[j] - t) > 0.001).any():
        return None
    g = gt.positions_xyz[j]
    finite = np.isfinite(g).all(axis=1)
    n = len(gt_t)
    start = finite & (j <= n // 2 - 1)
    end = finite & (j >= (n + 1) // 2 - 1)
    if start.sum() < 3 or end.sum() < 3:
        return None

    def align(mask):
        r, tt, s = geometry.umeyama_alignment(p[mask].T, g[mask].T, True)
        res = (s * (r @ p[mask].T)).T + tt - g[mask]
        return r, tt, s, math.sqrt((res**2).sum(axis=1).mean())

    try:
        rs, ts, ss, _ = align(start)
        re, te, se, _ = align(end)
        _, _, _, e_rmse = align(start | end)
    except geometry.GeometryException:
        return None
    a = (ss * (rs @ p.T)).T + ts
    b = (se * (re @ p.T)).T + te
    e_align = math.sqrt(((a - b) ** 2).sum(axis=1).mean())
    rel = re @ rs.T
    e_r = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1) / 2))))
    # T_drift = S_end S_start^-1: translation t_e - (s_e / s_s) R_e R_s^T t_s
    e_t = float(np.linalg.norm(te - (se / ss) * rel @ ts))
    return {"e_align": e_align, "e_s": ss / se, "e_r": e_r, "e_t": e_t, "e_rmse": e_rmse}


def bench_eval(binary, work, rounds):
    synth = work / "synth"
    sh(binary, "synth", "results", "-o", synth)
    pairs = [
        (run, synth / "dataset" / run.parent.name / "groundtruthSync.txt")
        for run in sorted((synth / "results").glob("*/*/*.txt"))
    ]
    assert len(pairs) == 1000, len(pairs)
    # the evo version computes the same numbers (where both succeed)
    worst = 0.0
    agree = 0
    for (e, g), r in zip(pairs, monovo.evaluate_many(pairs)):
        v = evo_evaluate(e, g)
        if v is None or not r.ok:
            agree += (v is None) == (not r.ok)
            continue
        agree += 1
        for k, x in v.items():
            worst = max(worst, abs(x - getattr(r, k)) / max(1.0, abs(x)))
    out = {"runs": len(pairs), "evo_same_status": agree, "evo_max_rel_diff": worst, "rounds": []}
    for _ in range(rounds):
        t0 = time.perf_counter()
        monovo.evaluate_many(pairs)
        t_many = time.perf_counter() - t0
        t0 = time.perf_counter()
        for e, g in pairs:
            monovo.evaluate(e, g)
        t_one = time.perf_counter() - t0
        t0 = time.perf_counter()
        for e, g in pairs:
            evo_evaluate(e, g)
        t_evo = time.perf_counter() - t0
        out["rounds"].append(
            {
                "monovo_evaluate_many_s": round(t_many, 4),
                "monovo_evaluate_loop_s": round(t_one, 4),
                "evo_s": round(t_evo, 3),
                "ratio_many": round(t_evo / t_many, 1),
                "ratio_loop": round(t_evo / t_one, 1),
            }
        )
    return out


def bench_frames(binary, work, rounds):
    seq = work / "seq"
    sh(binary, "synth", "sequence", "-o", seq, "--size", "1280x1024", "--frames", 300)
    out = {"frames": 300, "size": "1280x1024 JPEG -> 640x480", "rounds": []}
    for r in range(rounds):
        row = {}
        o = work / f"rect{r}"
        t0 = time.perf_counter()
        p = subprocess.run(
            [str(binary), "rectify", str(seq), "-o", str(o), "--compression", "none", "--json"],
            check=True, capture_output=True, text=True,
        )
        row["cli_rectify_fps"] = round(300 / (time.perf_counter() - t0), 1)
        for name, opts in [("raw", {}), ("rectified", {"rectify": True}),
                           ("photometric", {"rectify": True, "photometric": True})]:
            t0 = time.perf_counter()
            s = monovo.Sequence(seq, **opts)
            n = sum(1 for _ in s)
            row[f"python_{name}_fps"] = round(n / (time.perf_counter() - t0), 1)
        row["ratio_rectified_to_cli"] = round(row["python_rectified_fps"] / row["cli_rectify_fps"], 2)
        out["rounds"].append(row)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--monovo", default="target/release/monovo")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    import evo

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        result = {
            "tool": "xtask/peers/python_bench.py",
            "python": platform.python_version(),
            "numpy": np.__version__,
            "evo": evo.__version__,
            "monovo": monovo.__version__,
            "jpeg_decoder": monovo.JPEG_DECODER,
            "cores": os.cpu_count(),
            "evaluation": bench_eval(a.monovo, work, a.rounds),
            "frames": bench_frames(a.monovo, work, a.rounds),
        }
    json.dump(result, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
