#!/usr/bin/env bash
# The suite under stress (not collected by pytest; run by hand or by CI at the end):
#
#   tests/stress_suite.sh side-by-side   # two fresh clones, both suites started together
#   tests/stress_suite.sh busy           # one fresh clone, with two CPU-bound processes running
#   tests/stress_suite.sh all            # both, one after the other (the default)
#
# Each run is `python -m pytest -q -p no:randomly` from the clone's directory (so it imports the clone's
# urdaemon) with this checkout's virtualenv. It prints each run's exit code and wall time and exits
# non-zero if any run failed. Logs stay in $OUT (default: a new directory under /tmp).
#
# Environment: REPO (what to clone; default: this checkout; commits only, not uncommitted edits),
# PY (the interpreter; default: $REPO/.venv/bin/python), OUT, PYTEST_ARGS (extra pytest arguments),
# RUN_TIMEOUT (seconds per run; default 1800).
set -euo pipefail

MODE="${1:-all}"
REPO="${REPO:-$(git -C "$(dirname "$0")" rev-parse --show-toplevel)}"
PY="${PY:-$REPO/.venv/bin/python}"
OUT="${OUT:-$(mktemp -d /tmp/stress-suite.XXXXXX)}"
RUN_TIMEOUT="${RUN_TIMEOUT:-1800}"
read -r -a EXTRA <<<"${PYTEST_ARGS:-}"
FAILED=0
BURNERS=()

cleanup() {
    local pid
    for pid in "${BURNERS[@]}"; do
        kill "$pid" 2>/dev/null || true
    done
}
trap cleanup EXIT

clone() {  # clone NAME -> prints the clone's directory
    local dir="$OUT/$1"
    git clone -q "$REPO" "$dir"
    echo "$dir"
}

run_suite() {  # run_suite NAME DIR: the suite in DIR, log in $OUT/NAME.log, result in $OUT/NAME.result
    local name="$1" dir="$2" start end code
    start=$(date +%s.%N)
    set +e
    (
        cd "$dir"
        # the clone's urdaemon also in the scripts the tests start (the shared virtualenv's editable
        # install points at $REPO, and a script's own directory comes first on its sys.path)
        export PYTHONPATH="$dir${PYTHONPATH:+:$PYTHONPATH}"
        "$PY" -c "import urdaemon; print('testing', urdaemon.__file__)"
        timeout "$RUN_TIMEOUT" "$PY" -m pytest -q -p no:randomly "${EXTRA[@]}"
    ) >"$OUT/$name.log" 2>&1
    code=$?
    set -e
    end=$(date +%s.%N)
    printf '%s exit=%d wall=%.1fs %s\n' "$name" "$code" "$(echo "$end - $start" | bc)" \
        "$(tail -n 1 "$OUT/$name.log")" >"$OUT/$name.result"
}

report() {  # report NAME...: print each run's result; remember a failure
    local name line
    for name in "$@"; do
        line=$(cat "$OUT/$name.result")
        echo "$line"
        case "$line" in
            *" exit=0 "*) ;;
            *) FAILED=1 ;;
        esac
    done
}

side_by_side() {
    local a b pa pb
    a=$(clone side-a)
    b=$(clone side-b)
    echo "side by side: $a and $b, started together"
    run_suite side-a "$a" &
    pa=$!
    run_suite side-b "$b" &
    pb=$!
    wait "$pa" || true
    wait "$pb" || true
    report side-a side-b
}

busy() {
    local dir
    dir=$(clone busy)
    "$PY" -c "while True: pass" &
    BURNERS+=($!)
    "$PY" -c "while True: pass" &
    BURNERS+=($!)
    echo "busy: $dir with two CPU-bound processes (${BURNERS[*]})"
    run_suite busy "$dir"
    cleanup
    BURNERS=()
    report busy
}

echo "logs in $OUT (cloning $REPO at $(git -C "$REPO" rev-parse --short HEAD), $(nproc) cores)"
case "$MODE" in
    side-by-side) side_by_side ;;
    busy) busy ;;
    all) side_by_side; busy ;;
    *) echo "usage: $0 [side-by-side|busy|all]" >&2; exit 2 ;;
esac
if [ "$FAILED" -ne 0 ]; then
    echo "FAILED: see the logs in $OUT"
    exit 1
fi
echo "all runs passed"
