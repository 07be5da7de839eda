#!/usr/bin/env bash
# Install fingersplat3d and everything it needs on a fresh Debian/Ubuntu machine (idempotent).
#   bash tools/install.sh
# System libraries: Open3D needs libusb-1.0 (and libGL/libgomp on slim images).
# PyTorch is installed first and pinned to the 2.13.0 CPU build, so that nothing resolves a
# newer torch with several GB of CUDA wheels.
set -euo pipefail
cd "$(dirname "$0")/.."

missing=()
for lib in libusb-1.0.so.0:libusb-1.0-0 libGL.so.1:libgl1 libgomp.so.1:libgomp1; do
  ldconfig -p | grep -q "${lib%%:*}" || missing+=("${lib##*:}")
done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
fi

python3 -m pip install -q torch==2.13.0
python3 -m pip install -q -e ".[test]"
# The CPU rasterizer's numba kernels, compiled once now rather than during the first fuse (cached on disk).
python3 -m fingersplat3d.splat.warmup
