"""Runs every ```python block of a Markdown file (the README), each in a fresh interpreter, in a
scratch folder where `examples/` is the repository's, then examples/python/*.py with few
trials. Fails (exit 1) naming the block's first line in the file when one fails.
Usage: python scripts/readme-python.py README.md"""
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

root = Path(__file__).resolve().parents[1]
doc = Path(sys.argv[1]) if len(sys.argv) > 1 else root / "README.md"
text = doc.read_text()
failed = 0
with tempfile.TemporaryDirectory() as scratch:
    os.symlink(root / "examples", Path(scratch) / "examples")
    runs = []
    for m in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
        line = text[: m.start()].count("\n") + 2
        runs.append((f"{doc.name}:{line}", [sys.executable, "-c", m.group(1)]))
    for ex in sorted((root / "examples" / "python").glob("*.py")):
        runs.append((str(ex.relative_to(root)), [sys.executable, str(ex), "5", "example.png"]))
    if not runs:
        sys.exit(f"readme-python: no ```python block in {doc}")
    for name, cmd in runs:
        env = dict(os.environ, MPLBACKEND="Agg")
        r = subprocess.run(cmd, cwd=scratch, capture_output=True, text=True, env=env)
        status = "ok" if r.returncode == 0 else f"FAILED (exit {r.returncode})"
        print(f"readme-python: {name}: {status}")
        if r.returncode != 0:
            failed += 1
            print(r.stdout[-2000:], r.stderr[-4000:], sep="\n", file=sys.stderr)
sys.exit(1 if failed else 0)
