#!/bin/sh
# Rebuild three-viewer.min.js, the classic-script bundle the 3-D viewer loads, from the
# unmodified npm files in src/ (three@0.180.0: build/three.module.min.js, build/three.core.min.js,
# examples/jsm/controls/OrbitControls.js, examples/jsm/loaders/GLTFLoader.js,
# examples/jsm/utils/BufferGeometryUtils.js). Needs node; fetches esbuild from npm into a temp dir.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
(cd "$tmp" && npm init -y >/dev/null && npm install --no-audit --no-fund esbuild@0.25.10 >/dev/null)
"$tmp/node_modules/.bin/esbuild" "$here/src/entry.js" --bundle --minify --format=iife \
  --alias:three="$here/src/three.module.min.js" --legal-comments=eof \
  --outfile="$here/three-viewer.min.js"
