#!/usr/bin/env python3
"""Compares two spadgen dataset folders file by file: every file byte for byte, except in the samples'
metadata.json the "run" (timing) and "sense" (the folder read) sections. Hidden files (locks) are skipped.
Exit 0 when equal; else prints the differences and exits 1."""
import json
import os
import sys


def files(root):
    out = set()
    for d, _, names in os.walk(root):
        for n in names:
            if not n.startswith("."):
                out.add(os.path.relpath(os.path.join(d, n), root))
    return out


def main(a, b):
    fa, fb = files(a), files(b)
    bad = [f"only in {a}: {f}" for f in sorted(fa - fb)] + [f"only in {b}: {f}" for f in sorted(fb - fa)]
    for rel in sorted(fa & fb):
        pa, pb = os.path.join(a, rel), os.path.join(b, rel)
        if os.path.basename(rel) == "metadata.json":
            ma, mb = json.load(open(pa)), json.load(open(pb))
            for m in (ma, mb):
                m.pop("run", None)
                m.pop("sense", None)
            if ma != mb:
                bad.append(f"differs: {rel}")
        elif open(pa, "rb").read() != open(pb, "rb").read():
            bad.append(f"differs: {rel}")
    if len(fa) < 20:
        bad.append(f"only {len(fa)} files in {a}")
    for line in bad:
        print(line)
    print(f"compared {len(fa & fb)} files: {'equal' if not bad else 'NOT equal'}")
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
