#!/usr/bin/env bash
# Debian packages the project needs: headless OpenGL for pyrender (EGL via Mesa, OSMesa as the
# fallback), redis-server for the scaled-out queue and its tests, chromium for browser tests,
# ffmpeg for browser-playable video renditions, libgl1 + libglib2.0-0 for the cv2 build that
# mediapipe brings (opencv-contrib-python links libGL and libgthread), nginx-light and openssl for
# the browser test behind an HTTPS reverse proxy. Installs only what is missing.
set -euo pipefail
pkgs=(redis-server chromium libegl1 libgl1 libglib2.0-0 libgl1-mesa-dri libosmesa6 ffmpeg python3-venv
      nginx-light openssl)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "installing Debian packages: ${missing[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
