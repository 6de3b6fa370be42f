#!/usr/bin/env bash
# Installs everything tessera needs to build and test, from Debian 12's own packages.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends build-essential cmake pkg-config libopen3d-dev libopencv-dev libopenni2-dev libtbb-dev libgtest-dev libgmock-dev libeigen3-dev libv4l-dev libsqlite3-dev nlohmann-json3-dev libyaml-cpp-dev libcli11-dev libfmt-dev libspdlog-dev libfreenect-dev libtinyobjloader-dev libtinygltf-dev libcgal-dev libcpp-httplib-dev python3-prometheus-client libpqxx-dev postgresql
# The monitor page's end-to-end test drives Debian's chromium with playwright-core, pinned in
# tests/browser/package-lock.json. Node and npm come from Debian unless already installed.
$SUDO apt-get install -y -qq --no-install-recommends chromium
command -v npm > /dev/null || $SUDO apt-get install -y -qq --no-install-recommends nodejs npm
npm ci --prefix "$(dirname "$0")/../tests/browser" --no-audit --no-fund --loglevel=error
