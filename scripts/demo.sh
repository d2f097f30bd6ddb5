#!/usr/bin/env bash
# The main job on a built-in example: set up .venv (pinned), then predict on the example tower.
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh"
cd "$ROOT"
exec ipe demo "$@"
