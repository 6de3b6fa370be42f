#!/usr/bin/env bash
# Installs what tessera needs from Debian 12's own packages.
#   scripts/setup.sh           what building and running the tessera executable needs
#   scripts/setup.sh --tests   that, and what the test suite and benchmarks need besides:
#                              GoogleTest, a PostgreSQL server the fleet tests start and stop,
#                              a ROS master for the live ROS test, chromium and playwright-core
#                              (npm) for the monitor page's test
set -euo pipefail
tests=false
case "${1:-}" in
  "") ;;
  --tests) tests=true ;;
  *) echo "usage: scripts/setup.sh [--tests]" >&2; exit 2 ;;
esac
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
install() { $SUDO apt-get install -y -qq --no-install-recommends "$@"; }
$SUDO apt-get update -qq
install build-essential cmake pkg-config libopen3d-dev libopencv-dev libopenni2-dev libtbb-dev \
  libeigen3-dev libv4l-dev libsqlite3-dev nlohmann-json3-dev libyaml-cpp-dev libcli11-dev \
  libfmt-dev libspdlog-dev libfreenect-dev libtinyobjloader-dev libtinygltf-dev libcgal-dev \
  libcpp-httplib-dev libpqxx-dev
# ROS 1 (Debian's own): ROS bags (.bag), the ros:// source and the map published on a ROS graph
# (docs/ROS.md). tessera builds without them, leaving those out.
install libroscpp-dev librosbag-dev librosbag-storage-dev libsensor-msgs-dev libstd-msgs-dev \
  libgeometry-msgs-dev libtf2-msgs-dev libvisualization-msgs-dev libdiagnostic-msgs-dev
$tests || exit 0
# python3-rosmaster: the ROS master the live ROS test starts and stops.
install libgtest-dev libgmock-dev python3-prometheus-client postgresql chromium python3-rosmaster
# The monitor page's end-to-end test drives Debian's chromium with playwright-core, pinned in
# tests/browser/package-lock.json. Node and npm come from Debian unless already installed.
command -v npm > /dev/null || install nodejs npm
npm ci --prefix "$(dirname "$0")/../tests/browser" --no-audit --no-fund --loglevel=error
