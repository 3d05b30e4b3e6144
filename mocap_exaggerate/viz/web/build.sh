#!/bin/sh
# Rebuilds viewer.js, the page player (viewer_src.js) bundled with three.js into one minified
# script that page.py inlines, and LICENSE-three.txt beside it. Needs node and npm; three and
# esbuild are installed, at the versions pinned here, into a temporary folder that is removed after.
#
#   sh mocap_exaggerate/viz/web/build.sh
set -eu

THREE_VERSION=0.187.0
ESBUILD_VERSION=0.28.2

here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cd "$work"
npm init -y >/dev/null
npm install --no-audit --no-fund --save-exact "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION" >/dev/null
# The entry sits beside node_modules so that its imports of three resolve there.
cp "$here/viewer_src.js" entry.js
./node_modules/.bin/esbuild entry.js --bundle --minify --format=iife --target=es2020 --charset=utf8 \
    --banner:js="// mocap_exaggerate page player (viewer_src.js) bundled with three.js $THREE_VERSION (MIT licence, see LICENSE-three.txt) by esbuild $ESBUILD_VERSION; rebuild with build.sh" \
    --outfile=viewer.js
if grep -qi '</script' viewer.js; then
    echo "viewer.js holds '</script', which would end the page's script early" >&2
    exit 1
fi
cp viewer.js "$here/viewer.js"
cp node_modules/three/LICENSE "$here/LICENSE-three.txt"
echo "wrote $here/viewer.js ($(wc -c < "$here/viewer.js") bytes)"
