#!/usr/bin/env python2
"""The TUM RGB-D benchmark scripts' numbers for the cases of trajectory_metrics.py, at full
precision: this runs under Python 2 (the scripts are Python 2) with numpy, imports the
scripts' own functions from the folder given as the first argument and prints one JSON object
per case (the scripts print six decimals, not enough to compare to 1e-9).

    python2 xtask/peers/tum_rgbd_peer.py TUM_SCRIPTS_DIR < cases.json > tum.json

Per case it does what the script's main block does, with the case's options:
evaluate_ate.py: read_file_list, associate, align (Horn), the error statistics;
evaluate_rpe.py: random.seed(0), read_trajectory, evaluate_trajectory, the statistics (the
rotational ones in degrees; the script prints the rotational median in radians, a slip of
its print line: both are recorded).
"""
import json
import random
import sys

import numpy

sys.path.insert(0, sys.argv[1])
import associate  # noqa: E402
import evaluate_ate  # noqa: E402
import evaluate_rpe  # noqa: E402


def stats(e, k=1.0):
    e = numpy.array(e)
    return {
        "rmse": float(numpy.sqrt(numpy.dot(e, e) / len(e)) * k),
        "mean": float(numpy.mean(e) * k),
        "median": float(numpy.median(e) * k),
        "std": float(numpy.std(e) * k),
        "min": float(numpy.min(e) * k),
        "max": float(numpy.max(e) * k),
        "n": int(len(e)),
    }


def ate(case):
    p = case["params"]
    first = associate.read_file_list(case["reference"])
    second = associate.read_file_list(case["estimate"])
    matches = associate.associate(first, second, float(p.get("offset", 0.0)),
                                  float(p.get("max_difference", 0.02)))
    scale = float(p.get("scale", 1.0))
    first_xyz = numpy.matrix([[float(v) for v in first[a][0:3]] for a, b in matches]).transpose()
    second_xyz = numpy.matrix([[float(v) * scale for v in second[b][0:3]]
                               for a, b in matches]).transpose()
    rot, trans, trans_error = evaluate_ate.align(second_xyz, first_xyz)
    return {"translational": stats(trans_error)}


def rpe(case):
    p = case["params"]
    random.seed(0)
    gt = evaluate_rpe.read_trajectory(case["reference"])
    est = evaluate_rpe.read_trajectory(case["estimate"])
    result = evaluate_rpe.evaluate_trajectory(
        gt, est, int(p.get("max_pairs", 10000)), bool(p.get("fixed_delta", False)),
        float(p.get("delta", 1.0)), p.get("delta_unit", "s"), float(p.get("offset", 0.0)),
        float(p.get("scale", 1.0)))
    trans = numpy.array(result)[:, 4]
    rot = numpy.array(result)[:, 5]
    # each statistic in degrees as the script converts it: value * 180.0 / numpy.pi
    r = stats(rot)
    for k in ("rmse", "mean", "median", "std", "min", "max"):
        r[k] = r[k] * 180.0 / numpy.pi
    r["median_as_printed_rad"] = float(numpy.median(rot))
    return {"translational": stats(trans), "rotational_deg": r}


def main():
    cases = json.load(sys.stdin)
    out = []
    for c in cases:
        try:
            res = ate(c) if c["tool"] == "tum_ate" else rpe(c)
        except Exception as e:  # the script's own refusals are results too
            res = {"error": str(e)}
        res["id"] = c["id"]
        out.append(res)
    json.dump({"python": sys.version.split()[0], "numpy": numpy.__version__, "cases": out},
              sys.stdout, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
