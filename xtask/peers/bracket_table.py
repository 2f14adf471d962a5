#!/usr/bin/env python3
"""Turns the printed tables of bracket_scores.py into docs/response_brackets.json and the
Markdown tables of docs/response-brackets.md (one per score: `ls`, and `ml` where the
printed tables have it).

    python3 xtask/peers/bracket_table.py peers.txt monovo.txt --versions "..." \
        --json docs/response_brackets.json > table.md
"""
import argparse
import json

PEERS = ["debevec", "robertson", "tum2016"]


def read(paths):
    scores = {}
    for path in paths:
        for line in open(path):
            c = line.split()
            if len(c) < 5 or c[0] == "set":
                continue
            num = lambda v: None if v == "-" else float(v)
            row = {"ls": num(c[2]), "tri": num(c[3])}
            if len(c) >= 6:
                row["ml"] = num(c[4])
            row["failed_folds"] = int(c[-1])
            scores.setdefault(c[0], {})[c[1]] = row
    return scores


def table(s, score):
    """The Markdown table of one score."""
    print("| set | monovo | Debevec | Robertson | 2016 tool | best peer | monovo / best peer "
          "| monovo / best OpenCV |")
    print("|---|---:|---:|---:|---:|---|---:|---:|")
    for name in sorted(s):
        m = s[name]
        get = lambda k: m.get(k, {}).get(score)
        fmt = lambda k: "fails" if get(k) is None else f"{get(k):.2f}"
        peers = [(get(k), k) for k in PEERS if get(k) is not None]
        best = min(peers) if peers else (None, "-")
        mono = get("monovo")
        opencv = [get(k) for k in PEERS[:2] if get(k) is not None]
        ratio = "-" if mono is None or best[0] is None else f"{mono / best[0]:.3f}"
        ratio_cv = "-" if mono is None or not opencv else f"{mono / min(opencv):.3f}"
        print(f"| {name} | {fmt('monovo')} | {fmt('debevec')} | {fmt('robertson')} | "
              f"{fmt('tum2016')} | {best[1]} | {ratio} | {ratio_cv} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tables", nargs="+")
    ap.add_argument("--versions", default="")
    ap.add_argument("--json")
    a = ap.parse_args()
    s = read(a.tables)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"versions": a.versions, "sets": s}, fh, indent=1, sort_keys=True)
            fh.write("\n")
    table(s, "ls")
    if any("ml" in r for m in s.values() for r in m.values()):
        print()
        table(s, "ml")


if __name__ == "__main__":
    main()
