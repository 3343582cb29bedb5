#!/usr/bin/env bash
# The emulated headset's tools (`handblocks emulate headset`, tests/webxr_browser.rs): Node.js
# modules playwright-core (drives the system's Chromium; it never downloads a browser here) and
# iwer (Meta's WebXR emulation runtime: an emulated Quest with hand tracking), installed into
# target/webxr-node, never into the repository or onto the system. Chromium itself is a system
# package (scripts/packages.sh). Usage: scripts/webxr-tools.sh   (from anywhere; tests/run runs it)
set -euo pipefail
cd "$(dirname "$0")/.."
WEBXR_NODE=target/webxr-node
WEBXR_PACKAGES="playwright-core@1.65.2 iwer@2.5.0"
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    echo "webxr-tools: Node.js and npm are missing (Debian: apt-get install nodejs npm)" >&2
    exit 1
fi
if NODE_PATH="$WEBXR_NODE/node_modules" node -e 'const v = (p) => require(p + "/package.json").version; if (v("playwright-core") !== "1.65.2" || v("iwer") !== "2.5.0") process.exit(1)' >/dev/null 2>&1; then
    exit 0
fi
echo "webxr-tools: installing $WEBXR_PACKAGES into $WEBXR_NODE" >&2
mkdir -p "$WEBXR_NODE"
# shellcheck disable=SC2086
npm install --prefix "$WEBXR_NODE" --no-audit --no-fund --no-save -s $WEBXR_PACKAGES >&2
