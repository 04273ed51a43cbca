#!/usr/bin/env python3
"""Compares two summary.json files: every key of the old one must exist in the new one with an
equal value (bit-equal floats); keys only in the new one are ignored (added fields). Paths
listed with --ignore (prefix match, e.g. paper.claims) are reported but not counted.
Usage: compare-summaries.py OLD NEW [--ignore PATH]..."""
import json, sys

def walk(a, b, path, out):
    if isinstance(a, dict):
        if not isinstance(b, dict):
            out.append((path, "type")); return
        for k, v in a.items():
            if k not in b:
                out.append((f"{path}.{k}", "missing")); continue
            walk(v, b[k], f"{path}.{k}", out)
    elif isinstance(a, list):
        if not isinstance(b, list) or len(a) != len(b):
            out.append((path, "length")); return
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", out)
    elif a != b:
        out.append((path, f"{a!r} -> {b!r}"))

args = sys.argv[1:]
ignore = [args[i + 1] for i, x in enumerate(args) if x == "--ignore"]
files = [x for i, x in enumerate(args) if x != "--ignore" and (i == 0 or args[i - 1] != "--ignore")]
old, new = (json.load(open(f)) for f in files)
diffs = []
walk(old, new, "", diffs)
bad = [d for d in diffs if not any(d[0].lstrip(".").startswith(p) for p in ignore)]
for p, why in diffs:
    print(("  " if (p, why) in bad else "  (ignored) ") + f"{p}: {why}"[:300])
sys.exit(1 if bad else 0)
