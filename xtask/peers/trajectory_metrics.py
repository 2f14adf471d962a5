#!/usr/bin/env python3
"""The peers' numbers for `monovo ape`, `monovo rpe`, `monovo rpe --tum` and `monovo kitti`
on the real trajectory files of tests/fixtures, regenerated from the peers themselves:

* evo (pip install evo numpy): every case's flags are parsed by evo's own command-line
  parsers and run by evo's own `evo_ape` / `evo_rpe` code (in-process, `--save_results` to a
  temporary zip, read back with evo's `load_res_file`), so the numbers are the CLI's.
* the TUM RGB-D scripts evaluate_ate.py, evaluate_rpe.py and associate.py (Python 2; from
  https://vision.in.tum.de/data/datasets/rgbd-dataset/tools or the import of their SVN at
  github.com/jbriales/rgbd_benchmark_tools, src/rgbd_benchmark_tools/, commit 3be6ca4 "added
  license text"), run through tum_rgbd_peer.py under a Python 2.7 with numpy (numpy 1.16.6 is
  the last for Python 2: `python2 -m pip install --target DIR numpy==1.16.6`, then
  PYTHONPATH=DIR).
* the KITTI odometry devkit (devkit_odometry.zip from cvlibs.net, or any of its public copies:
  cpp/evaluate_odometry.cpp, matrix.cpp, matrix.h, mail.h), compiled by you, unmodified except
  that its `%f` outputs are printed with 9 significant digits: put these lines in a header
  `precise_printf.h` and compile with `g++ -O2 -include precise_printf.h -o evaluate_odometry
  evaluate_odometry.cpp matrix.cpp`:

      #include <cstdio>
      #include <iostream>
      #include <stdarg.h>
      #include <string.h>
      static int precise_fprintf(FILE *f, const char *fmt, ...) {
        char buf[4096]; size_t j = 0;
        for (size_t i = 0; fmt[i] && j < sizeof(buf) - 8; i++) {
          if (fmt[i] == '%' && fmt[i + 1] == 'f') { memcpy(buf + j, "%.9g", 4); j += 4; i++; }
          else buf[j++] = fmt[i];
        }
        buf[j] = 0;
        va_list a; va_start(a, fmt); int r = vfprintf(f, buf, a); va_end(a); return r;
      }
      #define fprintf precise_fprintf

  The devkit evaluates sequences 11..21 of data/odometry/poses against
  results/NAME/data/; this script lays out a scratch folder so (each case's sequences first,
  one-pose sequences after them, which give no segment) and reads back errors/*.txt,
  plot_error/avg_*.txt and stats.txt.

Usage (from the repository root; the evo virtual environment's python):

    TUM_SCRIPTS=/path/to/tum/scripts PYTHON2=python2 KITTI_DEVKIT=/path/to/evaluate_odometry \\
        TUM_SCRIPTS_SOURCE="where they came from" KITTI_DEVKIT_SOURCE="where it came from" \\
        /path/to/venv/bin/python xtask/peers/trajectory_metrics.py \\
        > tests/fixtures/metrics/peers.json

Peers whose variable is not set are left out. The cases' `args` are the command-line flags
of both evo and monovo (monovo accepts evo's spellings); the TUM cases give monovo's flags and
the script's options (`params`). crates/cli/tests/metrics.rs runs monovo on every case.
"""
import contextlib
import copy
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
DSO = "tests/fixtures/dso-family/trajectory/"
MET = "tests/fixtures/metrics/"

FR1_GT = DSO + "evo__test__data__freiburg1_xyz-groundtruth.txt"
FR1_ORB = DSO + "evo__test__data__freiburg1_xyz-ORB_kf_mono.txt"
FR1_SHORT = DSO + "evo__test__data__freiburg1_xyz-rgbdslam_drift_short.txt"
FR1_RGBD = MET + "evo__freiburg1_xyz-rgbdslam.txt"
FR1_DRIFT = MET + "evo__freiburg1_xyz-rgbdslam_drift.txt"
V101_GT = DSO + "evo__test__data__V101_gt.txt"
V101_VINS = DSO + "evo__test__data__V101_openvins.txt"
K04_GT = MET + "kitti_04_gt.txt"
K04_EST = DSO + "stereo_dso__data__04__result.txt"
K07_GT = MET + "kitti_07_gt.txt"
K07_EST = MET + "kitti_07_estimate.txt"


def evo_cases():
    """(tool, reference, estimate, format word, args)."""
    cases = []
    tum_pairs = [
        ("fr1_orb", FR1_GT, FR1_ORB),
        ("fr1_short", FR1_GT, FR1_SHORT),
        ("fr1_rgbd", FR1_GT, FR1_RGBD),
        ("fr1_drift", FR1_GT, FR1_DRIFT),
        ("v101", V101_GT, V101_VINS),
    ]
    ape_args = [
        [], ["-a"], ["-as"], ["-s"], ["--align_origin"], ["-s", "--align_origin"],
        ["-as", "--n_to_align", "10"], ["-a", "-r", "angle_deg"], ["-r", "angle_rad", "-as"],
        ["-a", "-r", "full"], ["-as", "-r", "rot_part"], ["-r", "point_distance", "-as"],
        ["-as", "--t_max_diff", "0.004"], ["-as", "--t_offset", "0.013", "--t_max_diff", "0.02"],
        ["-as", "--sync_method", "interpolation"],
        ["-a", "-r", "angle_deg", "--sync_method", "interpolation", "--t_offset", "-0.02"],
    ]
    rpe_args = [
        [], ["-as"], ["--delta", "10"], ["--delta", "10", "--all_pairs"],
        ["-as", "-d", "0.2", "-u", "m"], ["-as", "-d", "0.2", "-u", "m", "--all_pairs"],
        ["-d", "5", "-u", "d"], ["-d", "5", "-u", "d", "--all_pairs", "-t", "0.2"],
        ["-d", "0.1", "-u", "r"], ["-r", "angle_deg", "-d", "0.1", "-u", "m",
                                  "--pairs_from_reference"],
        ["-r", "full", "-d", "3"], ["-r", "rot_part", "-d", "2", "--all_pairs"],
        ["-r", "angle_rad"], ["-r", "point_distance", "-d", "5"],
        ["-r", "point_distance_error_ratio", "-d", "5"],
        ["-as", "--sync_method", "interpolation", "-d", "4"],
        ["--t_offset", "0.01", "--t_max_diff", "0.02", "-r", "angle_deg"],
    ]
    for name, ref, est in tum_pairs:
        for k, a in enumerate(ape_args):
            cases.append(("evo_ape", "%s_ape%02d" % (name, k), ref, est, "tum", a))
        for k, a in enumerate(rpe_args):
            cases.append(("evo_rpe", "%s_rpe%02d" % (name, k), ref, est, "tum", a))
    for name, ref, est in [("kitti04", K04_GT, K04_EST), ("kitti07", K07_GT, K07_EST)]:
        for k, a in enumerate([[], ["-as"], ["-a", "-r", "angle_deg"], ["-as", "-r", "full"],
                               ["--align_origin", "-r", "rot_part"]]):
            cases.append(("evo_ape", "%s_ape%02d" % (name, k), ref, est, "kitti", a))
        for k, a in enumerate([[], ["-as", "-d", "100", "-u", "m"], ["-r", "angle_deg", "-d", "10"],
                               ["-d", "50", "-u", "m", "--all_pairs", "-r", "angle_deg"],
                               ["-d", "20", "-u", "d"]]):
            cases.append(("evo_rpe", "%s_rpe%02d" % (name, k), ref, est, "kitti", a))
    return cases


def run_evo(cases):
    import numpy as np
    import scipy
    import evo
    from evo.cli import ape, ape_parser, rpe, rpe_parser
    from evo.tools import file_interface
    out = []
    tmp = tempfile.mkdtemp()
    for tool, cid, ref, est, fmt, args in cases:
        zpath = os.path.join(tmp, cid + ".zip")
        parser = (ape_parser if tool == "evo_ape" else rpe_parser).parser()
        argv = [fmt, os.path.join(ROOT, ref), os.path.join(ROOT, est)] + args + [
            "--save_results", zpath, "--no_warnings", "--silent"]
        ns = parser.parse_args(argv)
        entry = {"id": cid, "tool": tool, "reference": ref, "estimate": est, "args": args}
        try:
            # evo prints the progress of an all-pairs angle search to stdout
            with contextlib.redirect_stdout(sys.stderr):
                (ape if tool == "evo_ape" else rpe).run(ns)
            res = file_interface.load_res_file(zpath)
            stats = {k: float(v) for k, v in res.stats.items()}
            stats["n"] = int(len(res.np_arrays["error_array"]))
            entry["stats"] = stats
        except Exception as e:  # evo's refusals are results too
            entry["error"] = "%s: %s" % (type(e).__name__, e)
        out.append(entry)
    shutil.rmtree(tmp)
    return {"evo": evo.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
            "python": sys.version.split()[0], "cases": out}


def tum_cases():
    cases = []
    pairs = [("fr1_orb", FR1_GT, FR1_ORB), ("fr1_short", FR1_GT, FR1_SHORT),
             ("fr1_rgbd", FR1_GT, FR1_RGBD), ("fr1_drift", FR1_GT, FR1_DRIFT),
             ("v101", V101_GT, V101_VINS)]
    ate = [({}, []), ({"offset": 0.013}, ["--t_offset", "0.013"]),
           ({"max_difference": 0.005}, ["--t_max_diff", "0.005"]),
           ({"scale": 1.7}, ["--scale", "1.7"])]
    rpe = [
        ({"fixed_delta": True}, []),
        ({"fixed_delta": True, "delta": 0.5}, ["--delta", "0.5"]),
        ({"fixed_delta": True, "delta": 0.2, "delta_unit": "m"}, ["-d", "0.2", "-u", "m"]),
        ({"fixed_delta": True, "delta": 0.1, "delta_unit": "rad"}, ["-d", "0.1", "-u", "rad"]),
        ({"fixed_delta": True, "delta": 5, "delta_unit": "deg"}, ["-d", "5", "-u", "deg"]),
        ({"fixed_delta": True, "delta": 3, "delta_unit": "f"}, ["-d", "3", "-u", "f"]),
        ({"fixed_delta": False}, ["--all_pairs"]),
        ({"fixed_delta": True, "max_pairs": 50}, ["--max_pairs", "50"]),
        ({"fixed_delta": True, "offset": 0.01, "scale": 1.3},
         ["--t_offset", "0.01", "--scale", "1.3"]),
    ]
    for name, ref, est in pairs:
        for k, (p, a) in enumerate(ate):
            cases.append({"id": "%s_tumate%02d" % (name, k), "tool": "tum_ate",
                          "reference": ref, "estimate": est, "params": p, "args": a})
        for k, (p, a) in enumerate(rpe):
            cases.append({"id": "%s_tumrpe%02d" % (name, k), "tool": "tum_rpe",
                          "reference": ref, "estimate": est, "params": p, "args": a})
    return cases


def run_tum(cases, scripts, python2):
    here = os.path.dirname(os.path.abspath(__file__))
    absolute = copy.deepcopy(cases)
    for c in absolute:
        c["reference"] = os.path.join(ROOT, c["reference"])
        c["estimate"] = os.path.join(ROOT, c["estimate"])
    p = subprocess.run(shlex.split(python2) + [os.path.join(here, "tum_rgbd_peer.py"), scripts],
                       input=json.dumps(absolute), capture_output=True, text=True, check=True)
    res = json.loads(p.stdout)
    by_id = {r["id"]: r for r in res["cases"]}
    out = []
    for c in cases:
        r = by_id[c["id"]]
        e = dict(c)
        e.update({k: v for k, v in r.items() if k != "id"})
        out.append(e)
    return {"python": res["python"], "numpy": res["numpy"],
            "scripts": os.environ.get("TUM_SCRIPTS_SOURCE", scripts), "cases": out}


def run_kitti(devkit):
    sets = [("kitti04", [(K04_GT, K04_EST)]), ("kitti07", [(K07_GT, K07_EST)]),
            ("kitti04_07", [(K04_GT, K04_EST), (K07_GT, K07_EST)])]
    out = []
    for cid, seqs in sets:
        tmp = tempfile.mkdtemp()
        poses = os.path.join(tmp, "data", "odometry", "poses")
        data = os.path.join(tmp, "results", "peer", "data")
        os.makedirs(poses)
        os.makedirs(data)
        for i in range(11, 22):
            name = "%02d.txt" % i
            k = i - 11
            if k < len(seqs):
                shutil.copy(os.path.join(ROOT, seqs[k][0]), os.path.join(poses, name))
                shutil.copy(os.path.join(ROOT, seqs[k][1]), os.path.join(data, name))
            else:  # one pose: no segment
                for d in (poses, data):
                    open(os.path.join(d, name), "w").write("1 0 0 0 0 1 0 0 0 0 1 0\n")
        subprocess.run([devkit, "peer"], cwd=tmp, capture_output=True, check=True)
        res = os.path.join(tmp, "results", "peer")
        t_err, r_err = [float(v) for v in open(os.path.join(res, "stats.txt")).read().split()]
        lengths = []
        tl = open(os.path.join(res, "plot_error", "avg_tl.txt")).read().split("\n")
        rl = open(os.path.join(res, "plot_error", "avg_rl.txt")).read().split("\n")
        for a, b in zip(tl, rl):
            if a.strip():
                length, t = [float(v) for v in a.split()]
                _, r = [float(v) for v in b.split()]
                lengths.append({"length": length, "t_err": t, "r_err": r})
        segments = 0
        for k in range(len(seqs)):
            segments += len(open(os.path.join(res, "errors", "%02d.txt" % (11 + k))).read()
                            .strip().split("\n"))
        out.append({"id": cid, "sequences": [list(s) for s in seqs], "t_err": t_err,
                    "r_err": r_err, "segments": segments, "lengths": lengths,
                    "t_err_percent": t_err * 100.0,
                    "r_err_deg_per_100m": r_err * 180.0 / 3.141592653589793 * 100.0})
        shutil.rmtree(tmp)
    gpp = subprocess.run(["g++", "--version"], capture_output=True, text=True).stdout
    return {"compiler": gpp.split("\n")[0],
            "devkit": os.environ.get("KITTI_DEVKIT_SOURCE", devkit), "cases": out}


def main():
    result = {"generated_by": "xtask/peers/trajectory_metrics.py"}
    result["evo"] = run_evo(evo_cases())
    scripts, python2 = os.environ.get("TUM_SCRIPTS"), os.environ.get("PYTHON2", "python2")
    if scripts:
        result["tum"] = run_tum(tum_cases(), scripts, python2)
    devkit = os.environ.get("KITTI_DEVKIT")
    if devkit:
        result["kitti"] = run_kitti(devkit)
    json.dump(result, sys.stdout, indent=1, sort_keys=True)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
