#!/usr/bin/env bash
# System packages the build and the tests need, installed with apt when missing (as root, or
# through sudo):
# - ALSA's headers and pkg-config: the audio shell links against them (cpal, midir);
# - an X server with no screen, a screenshot tool and a converter (xvfb, x11-apps, netpbm) and
#   Mesa's software OpenGL (the editor's test draws the plugin's window on them; baseview loads
#   X11 and EGL at run time).
set -euo pipefail
missing=()
pkg-config --exists alsa 2>/dev/null || missing+=(libasound2-dev pkg-config)
command -v Xvfb > /dev/null || missing+=(xvfb)
command -v xwd > /dev/null || missing+=(x11-apps)
command -v xwdtopnm > /dev/null || missing+=(netpbm)
# What the editor's window loads: EGL and Mesa's software renderer, Xlib over XCB, xkbcommon.
# (and the VST3 editor's test clicks through XTest).
for lib in libEGL.so.1 libEGL_mesa.so.0 libX11-xcb.so.1 libxkbcommon-x11.so.0 libXtst.so.6; do
  ldconfig -p | grep -q "$lib" ||
    missing+=(libegl1 libegl-mesa0 libgl1-mesa-dri libx11-xcb1 libxkbcommon-x11-0 libxtst6)
done
[ -d /usr/lib/x86_64-linux-gnu/dri ] || missing+=(libgl1-mesa-dri)
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
sudo=""
if [ "$(id -u)" -ne 0 ]; then
  sudo="sudo"
fi
mapfile -t unique < <(printf '%s\n' "${missing[@]}" | sort -u)
echo "installing ${unique[*]}…" >&2
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${unique[@]}" >/dev/null
