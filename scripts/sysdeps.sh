#!/usr/bin/env bash
# Installs (or checks for) the system packages depthbench needs:
#   libusb-1.0   - pyrealsense2 loads it at import time
#   chromium     - the HTML leaderboard test opens the report headless (optional: that test skips)
set -u
need=()
ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' || need+=(libusb-1.0-0)
command -v chromium >/dev/null 2>&1 || need+=(chromium)
[ ${#need[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "sysdeps: installing ${need[*]} with apt-get"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q >/dev/null && apt-get install -y -q "${need[@]}" >/dev/null && exit 0
  echo "sysdeps: apt-get could not install: ${need[*]}" >&2
else
  echo "sysdeps: missing system packages: ${need[*]} (install them with your package manager, e.g. 'sudo apt-get install ${need[*]}')" >&2
fi
# libusb is required; chromium only enables one test.
ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0' || { echo "sysdeps: libusb-1.0 is required by pyrealsense2 and is missing" >&2; exit 1; }
exit 0
