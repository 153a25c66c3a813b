#!/bin/sh
# Cargo runner for x86_64-pc-windows-gnu: runs a Windows binary under Wine in the
# project's own prefix (target/wine/prefix, made by `cargo xtask setup`).
here=$(cd "$(dirname "$0")/.." && pwd)
export WINEPREFIX="${WINEPREFIX:-$here/target/wine/prefix}"
export WINEARCH=win64
export WINEDEBUG="${WINEDEBUG:--all}"
export WINEDLLOVERRIDES="mscoree,mshtml="
exec "$here/xtask/wine-run.sh" /usr/lib/wine/wine64 "$@"
