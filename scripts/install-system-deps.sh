#!/usr/bin/env bash
# Debian packages twisted uses beyond PyPI: PostgreSQL (server for the PostgreSQL store and its tests)
# and Mesa EGL/OSMesa (MuJoCo offscreen rendering for `twisted render`). Installs only what is missing.
set -u
need=()
if ! command -v initdb >/dev/null 2>&1 && ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
    need+=(postgresql)
fi
for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6; do
    dpkg -s "$pkg" >/dev/null 2>&1 || need+=("$pkg")
done
[ ${#need[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; else SUDO=; fi
$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need[@]}"
