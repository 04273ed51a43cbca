#!/usr/bin/env python3
"""Compares two output trees file by file (e.g. the folders scripts/compare-outputs.sh fills).

Usage: python3 scripts/compare-output-trees.py OLD_DIR NEW_DIR [strip]
With `strip`, JSON files equal once their `description` fields are removed count as
"differ only in description", and other differing text files print their changed lines.
reproduction.md is compared without its first line (the elapsed time)."""
import json, sys, os, difflib
a, b = sys.argv[1], sys.argv[2]
strip_desc = len(sys.argv) > 3
same = diff = 0
def walk(d):
    for r, _, fs in os.walk(d):
        for f in fs:
            yield os.path.relpath(os.path.join(r, f), d)
def nodesc(x):
    if isinstance(x, dict): return {k: nodesc(v) for k, v in x.items() if k != 'description'}
    if isinstance(x, list): return [nodesc(v) for v in x]
    return x
bad = []
for f in sorted(set(walk(a)) | set(walk(b))):
    if '.hushfuse-lock' in f: continue
    pa, pb = os.path.join(a, f), os.path.join(b, f)
    if not (os.path.exists(pa) and os.path.exists(pb)):
        bad.append(f'only one side: {f}'); continue
    A, B = open(pa, 'rb').read(), open(pb, 'rb').read()
    if f.endswith('reproduction.md'):
        A = b'\n'.join(A.split(b'\n')[1:]); B = b'\n'.join(B.split(b'\n')[1:])
    if A == B: same += 1; continue
    if strip_desc and f.endswith('.json') and 'manifest' not in f:
        if nodesc(json.loads(A)) == nodesc(json.loads(B)): diff += 1; continue
    if strip_desc:
        la, lb = A.decode(errors='replace').splitlines(), B.decode(errors='replace').splitlines()
        changed = [l for l in difflib.unified_diff(la, lb, lineterm='', n=0) if l[:1] in '+-' and not l.startswith(('+++', '---'))]
        bad.append(f'{f}: {len(changed)} changed lines, e.g. ' + ' | '.join(changed[:2])[:300])
    else:
        bad.append(f'differs: {f}')
print(f'{same} identical, {diff} differ only in description')
for x in bad: print(x)
sys.exit(1 if bad else 0)
