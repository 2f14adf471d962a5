#!/usr/bin/env python3
"""Fetches the real exposure brackets of brackets.tsv and makes their grey fixtures.

The images are not in the repository: their repositories carry no licence. This
downloads each image from GitHub at the commit listed in brackets.tsv (or takes it
from a local copy with --local ROOT, looked up as ROOT/SET/<file name>), checks its
sha256, and writes OUT/SET/indexed/NNNNN.ext, times.txt (`index index exposure_ms`)
and SOURCE.txt; prepare_brackets.py then makes the small grey fixtures:

    python3 xtask/peers/fetch_brackets.py /tmp/brackets-src
    for s in /tmp/brackets-src/*/; do
        python3 xtask/peers/prepare_brackets.py $s /tmp/brackets/$(basename $s) --max-side 320
    done
    venv/bin/python xtask/peers/bracket_scores.py /tmp/brackets/*/ --monovo target/release/monovo
"""
import argparse
import hashlib
import os
import sys
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))


def rows(path):
    with open(path) as fh:
        for lineno, line in enumerate(fh, 1):
            if not line.strip() or line.startswith("#"):
                continue
            cols = line.rstrip("\n").split("\t")
            if len(cols) != 6:
                sys.exit(f"{path}:{lineno}: expected 6 tab-separated columns, got {len(cols)}")
            yield cols


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--list", default=os.path.join(HERE, "brackets.tsv"))
    ap.add_argument("--local", metavar="ROOT", help="take the images from ROOT/SET/NAME")
    ap.add_argument("--only", nargs="*", help="these sets only")
    args = ap.parse_args()
    sets = {}
    for s, repo, commit, path, sha, exposure in rows(args.list):
        if args.only and s not in args.only:
            continue
        sets.setdefault(s, []).append((repo, commit, path, sha, exposure))
    for s, images in sets.items():
        dst = os.path.join(args.out, s)
        os.makedirs(os.path.join(dst, "indexed"), exist_ok=True)
        times = []
        for i, (repo, commit, path, sha, exposure) in enumerate(images):
            name = os.path.basename(path)
            if args.local:
                data = open(os.path.join(args.local, s, name), "rb").read()
            else:
                url = f"https://raw.githubusercontent.com/{repo}/{commit}/{path}"
                with urllib.request.urlopen(url, timeout=120) as r:
                    data = r.read()
            if hashlib.sha256(data).hexdigest() != sha:
                sys.exit(f"{s}: {path}: sha256 differs from brackets.tsv")
            ext = os.path.splitext(name)[1].lower()
            with open(os.path.join(dst, "indexed", f"{i:05d}{ext}"), "wb") as fh:
                fh.write(data)
            times.append(f"{i:05d} {i} {exposure}\n")
        with open(os.path.join(dst, "times.txt"), "w") as fh:
            fh.writelines(times)
        repo, commit, path = images[0][:3]
        with open(os.path.join(dst, "SOURCE.txt"), "w") as fh:
            fh.write(f"Set: {s}\nRepository: {repo}\nCommit: {commit}\n"
                     f"Path: {os.path.dirname(path)}/\nLicence: unknown (no LICENSE file)\n")
        print(f"{s}: {len(images)} images")


if __name__ == "__main__":
    main()
