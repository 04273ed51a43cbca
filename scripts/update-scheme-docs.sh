#!/usr/bin/env bash
# Regenerates the scheme reference of docs/scenarios.md (between its registry markers) from the
# registry itself: `hushfuse list-schemes --markdown`. A test fails when the two differ.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
python3 - "$(target/release/hushfuse list-schemes --markdown)" <<'PY'
import sys, re
gen = sys.argv[1]
p = "docs/scenarios.md"
s = open(p).read()
begin = s.index("<!-- registry:begin")
begin = s.index("\n", begin) + 1
end = s.index("<!-- registry:end -->")
s = s[:begin] + gen.rstrip("\n") + "\n" + s[end:]
open(p, "w").write(s)
PY
