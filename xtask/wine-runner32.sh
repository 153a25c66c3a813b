#!/bin/sh
# Cargo runner for i686-pc-windows-gnu: runs a 32-bit Windows binary under Wine's 32-bit
# loader (WoW64) in the project's own win64 prefix (target/wine/prefix, made by
# `cargo xtask setup`, which also installs wine32 and the 32-bit shim into syswow64).
here=$(cd "$(dirname "$0")/.." && pwd)
export WINEPREFIX="${WINEPREFIX:-$here/target/wine/prefix}"
export WINEARCH=win64
export WINEDEBUG="${WINEDEBUG:--all}"
export WINEDLLOVERRIDES="mscoree,mshtml="
exec "$here/xtask/wine-run.sh" /usr/lib/wine/wine "$@"
