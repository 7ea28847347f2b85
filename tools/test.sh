#!/usr/bin/env bash
# Set everything up (tools/setup.sh, idempotent) and run the whole test suite: plain pytest for the ROS-free
# core plus every rostest suite in test/ros (a real roscore and real nodes). Extra arguments go to pytest.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ENV_FILE="$(bash "$REPO/tools/setup.sh")"
set +u; . "$ENV_FILE"; set -u
cd "$REPO"
export LOCEM_NO_SKIP=1   # everything is installed here: a skipped test means broken setup (test/conftest.py)
exec python -m pytest -q -rfE --durations=25 "$@"   # the 25 slowest: where CI's time goes
