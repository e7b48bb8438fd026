#!/usr/bin/env bash
# Headless Chromium for tests/test_docs.py (the built documentation pages opened in a browser), from apt.
# Called by .ci/run; as root or with sudo -n. About 1-2 min.
set -euo pipefail
if command -v chromium >/dev/null 2>&1; then
    echo "install_chromium.sh: chromium found: $(command -v chromium)"
    exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo -n"; fi
$SUDO apt-get update -q
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends chromium
chromium --version
