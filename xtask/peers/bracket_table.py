#!/usr/bin/env python3
"""Turns the printed tables of bracket_scores.py into docs/response_brackets.json and the
Markdown table of docs/response-brackets.md.

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
            ls = None if c[2] == "-" else float(c[2])
            tri = None if c[3] == "-" else float(c[3])
            scores.setdefault(c[0], {})[c[1]] = {"ls": ls, "tri": tri, "failed_folds": int(c[4])}
    return scores


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
    print("| set | monovo | Debevec | Robertson | 2016 tool | best peer | monovo / best |")
    print("|---|---:|---:|---:|---:|---|---:|")
    for name in sorted(s):
        m = s[name]
        fmt = lambda k: "fails" if m.get(k, {}).get("ls") is None else f"{m[k]['ls']:.2f}"
        peers = [(m[k]["ls"], k) for k in PEERS if m.get(k, {}).get("ls") is not None]
        best = min(peers) if peers else (None, "-")
        mono = m.get("monovo", {}).get("ls")
        ratio = "-" if mono is None or best[0] is None else f"{mono / best[0]:.2f}"
        print(f"| {name} | {fmt('monovo')} | {fmt('debevec')} | {fmt('robertson')} | "
              f"{fmt('tum2016')} | {best[1]} | {ratio} |")


if __name__ == "__main__":
    main()
