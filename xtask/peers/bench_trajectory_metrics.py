#!/usr/bin/env python3
"""Times `monovo ape` / `monovo rpe` against evo on the same files and flags: evo's command
line (`evo_ape`, `evo_rpe`: a Python process per run, as a user or a script runs it) and evo's
Python API in one process (load, associate, align, metric: no interpreter start-up), each run
paired and alternated with monovo's command line (a process per run, start-up included).

    pip install evo numpy
    /path/to/venv/bin/python xtask/peers/bench_trajectory_metrics.py [--monovo target/release/monovo] [--rounds 3]

The cases are the evo cases of tests/fixtures/metrics/peers.json (real files: TUM RGB-D, EuRoC,
KITTI; every flag combination tested there). Prints one JSON object: per tool the total
seconds over all cases and rounds, and the ratios evo / monovo.
"""
import argparse
import contextlib
import json
import os
import subprocess
import sys
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def evo_api(tool, fmt, ref, est, args):
    """What evo_ape / evo_rpe do, through evo's own parser and run(), without plotting."""
    from evo.cli import ape, ape_parser, rpe, rpe_parser
    parser = (ape_parser if tool == "evo_ape" else rpe_parser).parser()
    ns = parser.parse_args([fmt, ref, est] + args + ["--silent", "--no_warnings"])
    with contextlib.redirect_stdout(sys.stderr):
        (ape if tool == "evo_ape" else rpe).run(ns)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--monovo", default=os.path.join(ROOT, "target", "release", "monovo"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--cli-cases", type=int, default=40,
                    help="cases for the evo command line (a second of start-up each)")
    a = ap.parse_args()
    evo_bin = os.path.dirname(sys.executable)
    peers = json.load(open(os.path.join(ROOT, "tests/fixtures/metrics/peers.json")))
    cases = [c for c in peers["evo"]["cases"] if "error" not in c]
    import evo  # noqa: F401  (imported once, as a script using the API would)
    t = {"monovo_cli": 0.0, "evo_api": 0.0, "monovo_cli_for_evo_cli": 0.0, "evo_cli": 0.0}
    runs = {"api": 0, "cli": 0}
    for r in range(a.rounds):
        for k, c in enumerate(cases):
            fmt = "kitti" if c["id"].startswith("kitti") else "tum"
            ref = os.path.join(ROOT, c["reference"])
            est = os.path.join(ROOT, c["estimate"])
            sub = "ape" if c["tool"] == "evo_ape" else "rpe"
            mono = [a.monovo, sub, fmt, ref, est] + c["args"] + ["--json"]
            # alternate which runs first
            order = (0, 1) if (r + k) % 2 == 0 else (1, 0)
            for which in order:
                s = time.perf_counter()
                if which == 0:
                    subprocess.run(mono, check=True, capture_output=True)
                    t["monovo_cli"] += time.perf_counter() - s
                else:
                    evo_api(c["tool"], fmt, ref, est, c["args"])
                    t["evo_api"] += time.perf_counter() - s
            runs["api"] += 1
            if k < a.cli_cases:
                evo = [os.path.join(evo_bin, c["tool"]), fmt, ref, est] + c["args"] + [
                    "--no_warnings"]
                for which in order:
                    s = time.perf_counter()
                    if which == 0:
                        subprocess.run(mono, check=True, capture_output=True)
                        t["monovo_cli_for_evo_cli"] += time.perf_counter() - s
                    else:
                        subprocess.run(evo, check=True, capture_output=True)
                        t["evo_cli"] += time.perf_counter() - s
                runs["cli"] += 1
    out = {
        "cases": len(cases), "rounds": a.rounds, "runs": runs,
        "seconds": {k: round(v, 4) for k, v in t.items()},
        "evo_api_over_monovo_cli": round(t["evo_api"] / t["monovo_cli"], 2),
        "evo_cli_over_monovo_cli": round(t["evo_cli"] / t["monovo_cli_for_evo_cli"], 2),
        "evo": peers["evo"]["evo"],
    }
    json.dump(out, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
