#!/usr/bin/env bash
# Run any command inside the project environment (set up first, idempotent), e.g.
#   tools/run.sh python bench/bench_locem.py
#   tools/run.sh rosrun locem_bridge locem_node
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ENV_FILE="$(bash "$REPO/tools/setup.sh")"
# source the environment with no positional parameters: ROS's setup scripts read them (a command's own
# --help would reach catkin's _setup_util.py and print its usage instead)
CMD=("$@"); set --
set +u; . "$ENV_FILE"; set -u
exec "${CMD[@]}"
