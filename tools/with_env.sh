#!/usr/bin/env bash
# Run a command inside the workspace environment (venv first on PATH, devel
# space sourced). Used by the Makefile: bash tools/with_env.sh CMD ARGS...
set -e
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
exec "$@"
