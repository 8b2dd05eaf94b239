#!/bin/sh
# System packages the project needs beyond Python: espeak-ng (speech for GET /v1/trips/{id}/advice.wav).
# Idempotent. Installs with apt-get when run as root on a Debian/Ubuntu machine; otherwise says what is
# missing and exits 0 (the service then answers 503 on the audio route and the audio test is skipped).
set -u
if command -v espeak-ng >/dev/null 2>&1; then
    echo "system-deps: espeak-ng present"
    exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "system-deps: installing espeak-ng with apt-get"
    if DEBIAN_FRONTEND=noninteractive apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq espeak-ng >/dev/null; then
        echo "system-deps: espeak-ng installed"
        exit 0
    fi
    echo "system-deps: apt-get could not install espeak-ng (offline?); speech stays unavailable"
    exit 0
fi
echo "system-deps: espeak-ng missing; install it (Debian/Ubuntu: sudo apt-get install espeak-ng; macOS uses its own speech engine)"
exit 0
