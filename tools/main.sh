#!/usr/bin/env bash
# Set everything up (tools/setup.sh, idempotent) and run the main job.
# Today: roscore + LOCEM, print the command catalogue through the real `rosservice call` CLI, then keep serving
# until Ctrl-C (with --once, or when CI is set, stop after printing).
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ENV_FILE="$(bash "$REPO/tools/setup.sh")"
set +u; . "$ENV_FILE"; set -u
cd "$REPO"
exec python -m locem_bridge.ros.main_job "$@"
