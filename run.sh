#!/usr/bin/env bash
# One entry point for a fresh machine with Python >= 3.11:
#   bash run.sh demo   set up .venv, then record, fuse and evaluate a synthetic throw (pslog demo)
#   bash run.sh test   set up .venv, then run ruff, mypy and the whole test suite
# Anything after the first word is passed on (to `pslog demo` or to pytest).
set -euo pipefail
cd "$(dirname "$0")"

PYTHON=${PYTHON:-python3}
VENV=${PSLOG_VENV:-.venv}
WARMING=""  # pslog.warm running in the background (setup background), its process id

setup() {  # setup [background]: pslog and its .[test] extras installed, the kernels compiled
           # (pslog.warm) while the extras install; with background, warm goes on after
           # setup (the caller waits for it with `warmed`)
    if [ ! -x "$VENV/bin/python" ]; then
        "$PYTHON" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "pslog needs Python >= 3.11, found " + sys.version.split()[0])'
        "$PYTHON" -m venv "$VENV"
    fi
    # reinstall only when the project's dependencies changed
    if [ ! -f "$VENV/.pslog-installed" ] || [ pyproject.toml -nt "$VENV/.pslog-installed" ]; then
        install -e .
        # numba compiles pslog's kernels on first use: do it now, once, announced (pslog/warm.py)
        echo "pslog: compiling the numba kernels (once per install, about 1.5 minutes)" >&2
        "$VENV/bin/python" -m pslog.warm >&2 &
        WARMING=$!
        # (stopped with this script, the install then not marked done; a failing check after
        # setup still waits for it)
        trap 'kill -TERM "$WARMING" 2>/dev/null; WARMING=""; exit 130' INT TERM
        trap warmed EXIT
    fi
    if [ ! -f "$VENV/.pslog-test-installed" ] || [ pyproject.toml -nt "$VENV/.pslog-test-installed" ]; then
        # the extras of .[test] (the test tools, and Ray, pyarrow, c3d for pslog batch and
        # the Parquet/C3D exports: a third of the download) while the kernels
        # compile, pslog itself not reinstalled under the running warm; pinned to what is
        # installed, so that nothing warm uses changes under it (should the tools need another
        # version of a core package: installed after warm, unpinned)
        local tools="$VENV/.pslog-test-tools.txt" pins="$VENV/.pslog-core-pins.txt"
        "$VENV/bin/python" -c 'import tomllib; print("\n".join(tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]["test"]))' > "$tools"
        "$VENV/bin/python" -m pip freeze --exclude-editable --disable-pip-version-check \
            | grep -E '^[A-Za-z0-9._-]+==' > "$pins" || true
        if ! install -c "$pins" -r "$tools" 2>/dev/null; then
            warmed
            install -r "$tools"
        fi
        touch "$VENV/.pslog-test-installed"
    fi
    if [ "${1:-}" != background ]; then
        warmed
    fi
}
UV=""  # uv in the venv once `install` has it (yes), or not to be had (no)

install() {  # install ARGS...: `pip install ARGS` into the venv, by uv where it can be had:
             # parallel downloads and bytecode compiled on every core (a fresh core install in
             # ~15 s against pip's ~40: the second core is idle while pip unpacks), else by pip
    if [ -z "$UV" ]; then
        UV=no
        if "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check uv \
                >/dev/null 2>&1 && "$VENV/bin/uv" --version >/dev/null 2>&1; then
            UV=yes
        fi
    fi
    if [ "$UV" = yes ]; then
        if "$VENV/bin/uv" pip install --quiet --python "$VENV/bin/python" --compile-bytecode "$@"; then
            return 0
        fi
        echo "pslog: uv could not install ($*); trying pip" >&2
    fi
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --upgrade pip
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check "$@"
}

warmed() {  # wait for setup's pslog.warm, then mark the install done
    if [ -n "$WARMING" ]; then
        wait "$WARMING" || true  # best effort: else the kernels compile on first use
        WARMING=""
        touch "$VENV/.pslog-installed"
    fi
}

case "${1:-}" in
    demo)
        shift
        setup
        exec "$VENV/bin/pslog" demo "$@"
        ;;
    test)
        shift
        setup background  # the kernels compile (two cores) while the extras install, ruff and mypy check
        "$VENV/bin/ruff" check pslog recorders viewers tests benchmarks tools samples
        "$VENV/bin/mypy"  # pslog/, as configured in pyproject.toml [tool.mypy]
        # the suite starts ~1,000 pslog processes; with PYTHONDONTWRITEBYTECODE set (as on
        # some CI images) each would compile pslog's sources again (~0.15-0.5 CPU s each):
        # write the bytecode once (only files changed since are compiled)
        # (best effort: a read-only checkout compiles in memory as before)
        "$VENV/bin/python" -m compileall -q pslog recorders viewers >/dev/null 2>&1 || true
        # likewise pytest's rewritten test modules (their asserts): each of the test processes
        # below would rewrite every one at its collection (~7 CPU s each); written once here
        # (~4.5 CPU s), read by all (tools/rewrite_tests.py; best effort as above)
        "$VENV/bin/python" tools/rewrite_tests.py tests >/dev/null 2>&1 || true
        warmed  # before the tests, which would compile what warm has not yet
        # three test processes (pytest-xdist), each running whole test files (--dist
        # loadfile: a module's shared fixture, e.g. a Ray cluster or a live run, is built
        # once); three on two cores: much of the suite waits (real-time recordings and live
        # runs, signals, Ray's start-ups), and a third process fills those waits;
        # PSLOG_TEST_PROCESSES=0 runs the suite in this process alone
        exec "$VENV/bin/python" -m pytest -n "${PSLOG_TEST_PROCESSES:-3}" --dist loadfile \
            --no-loadscope-reorder "$@"
        ;;
    *)
        echo "usage: bash run.sh demo|test [args...]" >&2
        exit 2
        ;;
esac
