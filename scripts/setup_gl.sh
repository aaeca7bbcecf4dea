#!/usr/bin/env bash
# Mesa's EGL for headless MuJoCo rendering of the depth camera (without it the camera falls
# back to ray casting, about 20x slower). Installs the Debian packages when it can (root, or
# sudo without a password); otherwise stops with one line naming the command to run.
set -euo pipefail
pkgs=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libglx-mesa0 libopengl0)
if ! command -v dpkg >/dev/null 2>&1; then
  exit 0  # not Debian-like: the Python check after this script decides
fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ]; then
  SUDO=()
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
  SUDO=(sudo -n)
else
  echo "depthnav: Mesa's EGL is missing (${missing[*]}); install it with: sudo apt-get install -y ${missing[*]}" >&2
  exit 1
fi
echo "depthnav: installing Mesa's EGL for headless rendering: ${missing[*]}"
"${SUDO[@]}" apt-get update -qq
DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
