#!/usr/bin/env bash
# The Python package's tests, from a fresh machine: a virtual environment under target/py/
# with the pinned tools (python/requirements-test.txt), clippy of the Python crate (it is
# not a default workspace member), the wheel built by maturin and installed, then pytest.
# Prints how long each part took. Part of README's test command (after `cargo test --release`).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
py=${PYTHON:-python3}
venv=target/py/venv
wheels=target/py/wheels
now() { date +%s.%N; }
took() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

# A fresh machine without Python (or without its venv module) gets Debian's.
if ! { command -v "$py" >/dev/null && "$py" -c "import venv, ensurepip" 2>/dev/null; }; then
    if command -v apt-get >/dev/null 2>&1; then
        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3 python3-venv python3-dev >/dev/null) || true
        py=python3
    fi
fi
command -v "$py" >/dev/null || { echo "test-python: $py not found (set PYTHON=...)" >&2; exit 1; }
t0=$(now)
# The tools' environment is made afresh whenever the pinned list changes (always, in a fresh
# clone such as CI's; HUSHFUSE_FRESH_VENV=1 forces it); the package is reinstalled every time.
stamp="$venv/.requirements"
if [ "${HUSHFUSE_FRESH_VENV:-0}" = 1 ] || ! cmp -s python/requirements-test.txt "$stamp"; then
    rm -rf "$venv"
    mkdir -p target/py
    "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install -q --disable-pip-version-check -r python/requirements-test.txt
    cp python/requirements-test.txt "$stamp"
fi
"$venv/bin/python" -m pip uninstall -q -y hushfuse >/dev/null 2>&1 || true
rm -rf "$wheels"
t_venv=$(took "$t0")

t1=$(now)
cargo clippy -p hushfuse-python --release -- -D warnings
t_clippy=$(took "$t1")

t2=$(now)
(cd python && "$root/$venv/bin/python" -m maturin build --release --quiet -i "$root/$venv/bin/python" --out "$root/$wheels")
"$venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps "$wheels"/hushfuse-*.whl
t_wheel=$(took "$t2")

# The command line, for the tests that compare Python with it: built as the integration tests
# build it (nothing to do after `cargo test --release`; `cargo build` would rebuild it with
# other features).
t_bin=$(now)
cargo test --release --quiet --no-run --test replay
t_bin=$(took "$t_bin")
export HUSHFUSE_BIN="${CARGO_TARGET_DIR:-$root/target}/release/hushfuse"
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1

t3=$(now)
# From target/py, so that the installed package is imported, not python/hushfuse.
set +e
(cd target/py && "$root/$venv/bin/python" -m pytest -q -p no:cacheprovider "$root/python/tests")
rc=$?
set -e
t_pytest=$(took "$t3")

# Every Python example of the README (and examples/python/), as a reader runs it: a fresh
# virtual environment with the wheel and its "examples" extra (pandas, matplotlib; the pinned
# versions), each block run in a scratch folder.
t4=$(now)
readme_venv=target/py/readme-venv
rm -rf "$readme_venv"
"$py" -m venv "$readme_venv"
wheel=$(ls "$wheels"/hushfuse-*.whl)
"$readme_venv/bin/python" -m pip install -q --disable-pip-version-check -c python/requirements-test.txt "$wheel[examples]"
set +e
"$readme_venv/bin/python" scripts/readme-python.py README.md
rc_readme=$?
set -e
t_readme=$(took "$t4")
echo "test-python: venv + pinned tools ${t_venv} s, clippy (python crate) ${t_clippy} s, wheel build + install ${t_wheel} s, command line ${t_bin} s, pytest ${t_pytest} s, README examples (fresh venv) ${t_readme} s"
if [ "$rc" -eq 5 ]; then
    echo "test-python: pytest collected no tests: failing" >&2
    exit 1
fi
if [ "$rc" -eq 0 ] && [ "$rc_readme" -ne 0 ]; then
    echo "test-python: a README example failed" >&2
    exit 1
fi
exit "$rc"
