#!/usr/bin/env python3
"""Where on the response each method wins or loses the leave-one-exposure-out scores of
bracket_scores.py: its squared errors split by each scored pixel's *top value*, the value in
its longest training frame with a value in 1..254. Under the least-squares merge that frame
dominates the pixel's irradiance (its weight is t^2), so the top value says which codes of the
table the prediction went through.

It reads the fitted tables that `bracket_scores.py --json` stores (every method, every fold;
several JSON files may be given, the later ones add methods or replace them) and scores them
again on the same folds; no method is run.

    venv/bin/python xtask/peers/bracket_scores.py SETS... --monovo target/release/monovo \\
        --json scores.json
    venv/bin/python xtask/peers/bracket_breakdown.py SETS... --scores scores.json \\
        [--score ls] [--split 250] [--json breakdown.json]

It prints, per set, the share of scored pixels whose top value is at or above --split, and
for each method the RMS error (grey levels) of the pixels below and above the split and of
all of them; then a Markdown table of monovo over the best OpenCV method in each part.
"""
import argparse
import json
import os
import shutil
import sys

import numpy as np

from bracket_scores import fold_residuals, groups, load_set

OPENCV = ["debevec", "robertson"]


def tables_of(paths):
    """{set: {method: [table per fold]}} from bracket_scores.py JSON files."""
    out = {}
    for path in paths:
        with open(path) as fh:
            doc = json.load(fh)
        for name, res in doc.get("sets", {}).items():
            for method, r in res.get("methods", {}).items():
                if r.get("tables"):
                    out.setdefault(name, {})[method] = r["tables"]
    return out


def breakdown(folder, tables, score, split):
    """{method: (sse_below, n_below, sse_above, n_above)} of one set."""
    frames, times = load_set(folder)
    folds = groups(times)
    res = {}
    for method, per_fold in tables.items():
        if len(per_fold) != len(folds):
            raise SystemExit(f"{folder}: {method} has {len(per_fold)} tables for "
                             f"{len(folds)} folds (were the scores made from this folder?)")
        acc = np.zeros(4)
        for (_, test), u in zip(folds, per_fold):
            if u is None:
                acc = np.array([np.nan, 0.0, np.nan, 0.0])
                break
            train = [i for i in range(len(frames)) if i not in test]
            r_ls, _, _, r_ml, top = fold_residuals(frames, times, train, test, np.array(u))
            r = r_ls if score == "ls" else r_ml
            above = top >= split
            acc += [r[~above] @ r[~above], (~above).sum(), r[above] @ r[above], above.sum()]
        res[method] = acc
    return res


def rms(sse, n):
    return float(np.sqrt(sse / n)) if n > 0 and np.isfinite(sse) else None


def fmt(v):
    return "-" if v is None else f"{v:.3f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sets", nargs="+", help="bracket folders (as given to bracket_scores.py)")
    ap.add_argument("--scores", nargs="+", required=True,
                    help="JSON files of bracket_scores.py with their tables")
    ap.add_argument("--score", choices=["ls", "ml"], default="ls")
    ap.add_argument("--split", type=int, default=250,
                    help="top values at or above this are the upper part (default 250)")
    ap.add_argument("--json", metavar="FILE", help="write the breakdown here")
    args = ap.parse_args()
    if not 2 <= args.split <= 254:
        raise SystemExit(f"--split {args.split}: expected a grey value in 2..254")
    tables = tables_of(args.scores)
    out = {"tool": "xtask/peers/bracket_breakdown.py", "score": args.score,
           "split": args.split, "sets": {}}
    rows = []
    lo, hi = f"top < {args.split}", f"top >= {args.split}"
    print(f"{'set':<28} {'method':<10} {'share':>6} {lo:>12} {hi:>12} {'all':>8}")
    for folder in args.sets:
        name = os.path.basename(os.path.normpath(folder))
        if name not in tables:
            raise SystemExit(f"{folder}: no tables for set {name} in {', '.join(args.scores)}")
        res = breakdown(folder, tables[name], args.score, args.split)
        entry = {}
        for method, (sb, nb, sa, na) in res.items():
            share = na / (na + nb) if na + nb > 0 else None
            entry[method] = {"share_above": share, "below": rms(sb, nb), "above": rms(sa, na),
                             "all": rms(sb + sa, nb + na)}
            print(f"{name:<28} {method:<10} {fmt(share):>6} {fmt(entry[method]['below']):>12} "
                  f"{fmt(entry[method]['above']):>12} {fmt(entry[method]['all']):>8}")
        sys.stdout.flush()
        out["sets"][name] = entry
        peers = [m for m in OPENCV if m in entry and entry[m]["all"] is not None]
        if "monovo" in entry and peers:
            best = min(peers, key=lambda m: entry[m]["all"])
            ratio = lambda part: (entry["monovo"][part] / entry[best][part]
                                  if entry["monovo"][part] and entry[best][part] else None)
            rows.append((name, entry["monovo"]["share_above"], best, ratio("below"),
                         ratio("above"), ratio("all")))
    if rows:
        print()
        print(f"| set | share of pixels with top value >= {args.split} | best OpenCV method "
              f"| monovo / it, top < {args.split} | top >= {args.split} | all |")
        print("|---|---:|---|---:|---:|---:|")
        for name, share, best, b, a, al in rows:
            print(f"| {name} | {fmt(share)} | {best} | {fmt(b)} | {fmt(a)} | {fmt(al)} |")
    if args.json:
        tmp = args.json + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(out, fh, indent=1, sort_keys=True)
            fh.write("\n")
        shutil.move(tmp, args.json)


if __name__ == "__main__":
    main()
