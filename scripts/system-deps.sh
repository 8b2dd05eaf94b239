#!/bin/sh
# System packages the project needs beyond Python, installed with Debian's apt-get when run as root.
# Idempotent: only what is missing is installed, in one apt-get call (waiting for another apt's lock).
# Without root or apt-get it says what is missing and exits 0: the features that need a package then
# say so (the audio route answers 503) and the tests that need it are skipped.
#
# One line per package in NEEDS: "<command that proves it is installed> <Debian package> <what for>".
set -u
NEEDS='
espeak-ng espeak-ng speech for GET /v1/trips/{id}/advice.wav
chromium chromium headless browser for the phone app tests (tests/browser)
mosquitto mosquitto MQTT broker for live SPaT (make antwerp, tests/spat_feed/test_mqtt.py)
'
missing=""
for_what=""
while read -r cmd pkg why; do
    [ -n "$cmd" ] || continue
    if command -v "$cmd" >/dev/null 2>&1; then
        echo "system-deps: $pkg present"
    else
        missing="$missing $pkg"
        for_what="$for_what; $pkg ($why)"
    fi
done <<EOF
$NEEDS
EOF
[ -n "$missing" ] || exit 0
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "system-deps: installing$missing with apt-get"
    apt="apt-get -o DPkg::Lock::Timeout=600 -qq"
    # shellcheck disable=SC2086  # word splitting of the package list is wanted
    if DEBIAN_FRONTEND=noninteractive $apt update && DEBIAN_FRONTEND=noninteractive $apt install -y --no-install-recommends $missing >/dev/null; then
        echo "system-deps: installed$missing"
        exit 0
    fi
    echo "system-deps: apt-get could not install$missing (offline?)${for_what}: unavailable"
    exit 0
fi
echo "system-deps: missing$missing${for_what}; install them with your package manager (Debian/Ubuntu: sudo apt-get install$missing)"
exit 0
