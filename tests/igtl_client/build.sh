#!/usr/bin/env bash
# Build the reference-library OpenIGTLink client: tests/igtl_client/build.sh OUT_BINARY
# Include and library paths from the package's CMake config (Debian: libopenigtlink-dev).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:-$here/igtl_client}"
config="${OPENIGTLINK_CONFIG:-/usr/lib/openigtlink/OpenIGTLinkConfig.cmake}"
inc="$(sed -n 's/^SET(OpenIGTLink_INCLUDE_DIRS "\(.*\)" *)/\1/p' "$config")"
lib="$(sed -n 's/^SET(OpenIGTLink_LIBRARY_DIRS "\(.*\)" *)/\1/p' "$config")"
"${CXX:-c++}" -std=c++11 -O1 -w -I"$inc" "$here/client.cxx" -o "$out" -L"$lib" -lOpenIGTLink -lpthread
