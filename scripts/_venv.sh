# Sourced by scripts/demo.sh and scripts/test.sh: create or update .venv with the pinned wheels.
# Re-installs only when requirements.txt or setup.py changed (a stamp holds their hash).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${IPE_VENV:-$ROOT/.venv}"
PYTHON="${PYTHON:-python3}"

if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "ipe_ros needs Python >= 3.11 (found $("$PYTHON" --version 2>&1)); set PYTHON=/path/to/python3.11" >&2
  exit 1
fi
if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" -m venv "$VENV"
fi
stamp="$VENV/.ipe_ros-installed"
want="$(cat "$ROOT/requirements.txt" "$ROOT/setup.py" "$ROOT/setup.cfg" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setting up $VENV (pinned wheels from requirements.txt; log: $VENV/install.log)" >&2
  if ! { "$VENV/bin/python" -m pip install --disable-pip-version-check -r "$ROOT/requirements.txt" &&
         "$VENV/bin/python" -m pip install --disable-pip-version-check --no-deps --no-build-isolation -e "$ROOT"; \
       } > "$VENV/install.log" 2>&1; then
    tail -n 30 "$VENV/install.log" >&2
    echo "installing into $VENV failed (full log: $VENV/install.log)" >&2
    exit 1
  fi
  echo "$want" > "$stamp"
fi
# DDS stays on this machine: without this Fast DDS multicasts on the network interface.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export PATH="$VENV/bin:$PATH"
