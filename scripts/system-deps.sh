#!/usr/bin/env bash
# Debian libraries that open3d needs at import (and Chromium for the browser tests with --test).
# Installs what is missing when running as root; otherwise names the packages and stops.
set -euo pipefail

want=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_lib libusb-1.0.so.0 || want+=(libusb-1.0-0)
have_lib libGL.so.1 || want+=(libgl1)
have_lib libgomp.so.1 || want+=(libgomp1)
if [ "${1:-}" = "--test" ]; then
    command -v chromium >/dev/null 2>&1 || want+=(chromium)
fi

[ ${#want[@]} -eq 0 ] && exit 0

if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing system packages: ${want[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${want[@]}" >/dev/null
else
    echo "error: missing system packages: ${want[*]}" >&2
    echo "install them first, e.g.: sudo apt-get install ${want[*]}" >&2
    exit 1
fi
