#!/usr/bin/env bash
# Re-fetch the vendored three.js files from the npm registry (unmodified copies).
# The HTML viewer (ncgen/viz/html.py) inlines them into every page it writes.
set -euo pipefail
VERSION=${1:-0.170.0}
here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm pack "three@$VERSION" >/dev/null && tar xzf "three-$VERSION.tgz")
cp "$tmp/package/build/three.module.min.js" "$tmp/package/examples/jsm/controls/OrbitControls.js" \
   "$tmp/package/LICENSE" "$here/"
echo "$VERSION" > "$here/VERSION"
