#!/usr/bin/env python3
"""Writes crates/synthetic/data/dorf.txt: real measured camera responses for the synthetic
sensors, a subset of the DoRF database (Grossberg and Nayar, "Modeling the space of camera
response functions", PAMI 2004; Columbia CAVE; research use, cite the paper).

Input: the 201 curves as plain text in dorfCurves.txt's layout (name / type / "I =" / 1024
irradiances / "B =" / 1024 brightnesses), e.g. rewritten from utils/201_CRF_data.mat of
github.com/GuoShi28/CBDNet (commit 083c2e1, Apache-2.0). Chosen: the curves without a
plateau (B strictly increasing over the irradiance range), at evenly spaced quantiles of
their mean brightness, so that the subset spans near-linear to strongly compressive curves.

    python3 xtask/peers/dorf_subset.py dorf201.txt crates/synthetic/data/dorf.txt --count 16
"""
import argparse
import numpy as np


def read(path):
    lines = [l.strip() for l in open(path)]
    curves = []
    i = 0
    while i + 5 < len(lines):
        name = lines[i]
        irr = np.array(lines[i + 3].split(), float)
        bri = np.array(lines[i + 5].split(), float)
        curves.append((name, irr, bri))
        i += 6
    return curves


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("src")
    ap.add_argument("out")
    ap.add_argument("--count", type=int, default=16)
    a = ap.parse_args()
    curves = read(a.src)
    ok = []
    for idx, (name, irr, bri) in enumerate(curves):
        if len(bri) != 1024 or not np.allclose(irr, np.arange(1024) / 1023, atol=1e-5):
            continue
        if bri[0] != 0 or abs(bri[-1] - 1) > 1e-6 or np.any(np.diff(bri) <= 0):
            continue
        ok.append((bri.mean(), idx, bri))
    ok.sort()
    pick = [ok[int(round(q))] for q in np.linspace(0, len(ok) - 1, a.count)]
    with open(a.out, "w") as fh:
        fh.write("# DoRF camera responses (Grossberg & Nayar 2004, Columbia CAVE; research use):\n")
        fh.write(f"# {a.count} of the 201 curves, chosen by xtask/peers/dorf_subset.py from the\n")
        fh.write("# strictly increasing ones at evenly spaced quantiles of their mean brightness.\n")
        fh.write("# One curve a line: its index among the 201, then the brightness B at the irradiances\n")
        fh.write("# i / 1023, i = 0..1023 (B(0) = 0, B(1) = 1).\n")
        for mean, idx, bri in pick:
            fh.write(f"{idx} " + " ".join(f"{v:.6g}" for v in bri) + "\n")
    print(f"{len(ok)} strictly increasing of {len(curves)}; wrote {a.count}:",
          [p[1] for p in pick], [round(p[0], 3) for p in pick])


if __name__ == "__main__":
    main()
