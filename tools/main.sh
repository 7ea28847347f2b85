#!/usr/bin/env bash
# Set everything up (tools/setup.sh, idempotent) and run the main job: the whole simulated plasterboard job
# (roslaunch locem_bridge plasterboard.launch, headless, automatic operator, embedded defaults) with its progress,
# then the report's process and outcome tables and where the report is. Exit 0 when every process succeeded.
# Arguments go to python -m locem_bridge.ros.main_job (--help lists them, e.g. --validate-lines, --time-scale 5).
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ENV_FILE="$(bash "$REPO/tools/setup.sh")"
set +u; . "$ENV_FILE"; set -u
cd "$REPO"
exec python -m locem_bridge.ros.main_job "$@"
