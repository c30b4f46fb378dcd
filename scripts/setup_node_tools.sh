#!/usr/bin/env bash
# Installs PlayCanvas's splat-transform (the splat ecosystem's own converter) into build/node_tools, pinned, so the
# format tests can compare our readers with files the ecosystem writes. Needs node >= 18 and npm (Debian 12 has 18,
# Debian 13 has 20; scripts/test.sh has scripts/setup.sh --node install them from apt); safe to run again.
# 2.7.1 is the newest release whose package.json accepts node 18/20 (3.x asks for node >= 22).
set -euo pipefail
cd "$(dirname "$0")/.."
VERSION=2.7.1
DEST=build/node_tools
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "[node_tools] node/npm not found (scripts/setup.sh --node installs them from apt): the splat-transform" \
       "comparison tests will be skipped" >&2
  exit 0
fi
major=$(node -p 'process.versions.node.split(".")[0]')
if [ "$major" -lt 18 ]; then
  echo "[node_tools] node $(node --version) is older than 18: splat-transform $VERSION needs 18+; tests skipped" >&2
  exit 0
fi
bin="$DEST/node_modules/.bin/splat-transform"
if [ -x "$bin" ] && [ "$(node -p "require('./$DEST/node_modules/@playcanvas/splat-transform/package.json').version")" = "$VERSION" ]; then
  exit 0
fi
echo "[node_tools] installing @playcanvas/splat-transform@$VERSION into $DEST"
mkdir -p "$DEST"
[ -f "$DEST/package.json" ] || echo '{"name": "gs-ibl-node-tools", "private": true}' > "$DEST/package.json"
npm install --prefix "$DEST" --no-audit --no-fund --loglevel=error --save-exact "@playcanvas/splat-transform@$VERSION"
"$bin" --version >/dev/null 2>&1 || "$bin" --help >/dev/null 2>&1 || true
echo "[node_tools] ready: $bin"
