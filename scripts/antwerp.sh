#!/bin/sh
# `make antwerp`: the advisory service with its advice from the Antwerp controller K648, as in a city:
# a real MQTT broker (mosquitto), the recorded day played onto the present clock and published per
# intersection (python -m spat_feed --log ... --mqtt ...), and the service subscribed to the broker.
# The broker takes no anonymous client: K648's topic may be published by K648's credentials only, the service
# reads with its own read-only ones (python -m spat_feed.transport.broker writes them, docs/SPAT.md section 5).
# Trips on corridor antwerp_k648 (spat_feed/presets/live) read signal group 1 of K648; the paper corridors
# stay simulated in process. Stop with Ctrl-C (the broker and the player stop too).
#   ANTWERP_LOG  the recording (default ../shared/data/spat/antwerp-2019-05-01.csv.gz)
#   MQTT_PORT    the broker's loopback port (default 1883); PORT the service's (default 8000)
set -eu
LOG=${ANTWERP_LOG:-../shared/data/spat/antwerp-2019-05-01.csv.gz}
[ -f "$LOG" ] || [ -n "${ANTWERP_LOG:-}" ] || LOG=../../shared/data/spat/antwerp-2019-05-01.csv.gz  # from a git worktree
MQTT_PORT=${MQTT_PORT:-1883}
PORT=${PORT:-8000}
BROKER=$(command -v mosquitto || echo /usr/sbin/mosquitto)
[ -x "$BROKER" ] || { echo "antwerp: mosquitto is not installed (sh scripts/system-deps.sh as root installs it)"; exit 1; }
[ -f "$LOG" ] || { echo "antwerp: no recording at $LOG (set ANTWERP_LOG)"; exit 1; }
dir=$(mktemp -d)
.venv/bin/python -m spat_feed.transport.broker "$dir" --port "$MQTT_PORT" --controller k648=648 --reader service >/dev/null
"$BROKER" -c "$dir/mosquitto.conf" &
broker=$!
SPAT_MQTT_URL=$(cat "$dir/k648.url") .venv/bin/python -m spat_feed --port 8765 --corridors none --log "$LOG" --loop &
player=$!
trap 'kill $broker $player 2>/dev/null; rm -rf "$dir"' EXIT INT TERM
echo "antwerp: broker on 127.0.0.1:$MQTT_PORT, player of $LOG; service on http://127.0.0.1:$PORT (corridor antwerp_k648; /health shows intersection 648)"
ECO_SPAT_MQTT_URL=$(cat "$dir/service.url") ECO_SPAT_SIMULATE=true ECO_CORRIDOR_DIR=spat_feed/presets/live \
    .venv/bin/ecodrive serve --port "$PORT"
