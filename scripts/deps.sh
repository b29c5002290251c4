#!/usr/bin/env bash
# System packages the audio shell links against: ALSA's headers (cpal, midir) and pkg-config to
# find them. Installs them with apt when they are missing (as root, or through sudo).
set -euo pipefail
if pkg-config --exists alsa 2>/dev/null; then
  exit 0
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  sudo="sudo"
fi
echo "installing libasound2-dev and pkg-config (needed by cpal and midir)…" >&2
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq libasound2-dev pkg-config >/dev/null
