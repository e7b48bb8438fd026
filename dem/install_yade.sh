#!/usr/bin/env bash
# Install the Yade DEM engine (Debian/Ubuntu package "yade"; tested with 2023.02a on Debian 12).
# Idempotent: does nothing when `yade` is already on PATH. Needs root (or sudo) and network access to apt.
set -euo pipefail
if command -v yade >/dev/null 2>&1; then
    echo "yade already installed: $(command -v yade)"
    exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    SUDO="sudo"
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update
$SUDO apt-get install -y yade
command -v yade >/dev/null 2>&1 || { echo "yade not on PATH after installation" >&2; exit 1; }
echo "yade installed: $(command -v yade)"
