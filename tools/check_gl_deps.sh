#!/bin/sh
# Mesa's EGL and software rasteriser (llvmpipe) are needed for headless rendering and the render tests.
missing=""
for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing="$missing $pkg"
done
[ -z "$missing" ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
    echo "note: Mesa EGL packages not found ($missing); install your distribution's EGL + Mesa DRI packages."
    exit 0
fi
if [ "$(id -u)" = "0" ]; then
    echo "installing Mesa EGL for headless OpenGL:$missing"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing
else
    echo "Headless OpenGL needs:$missing"
    echo "Run: sudo apt-get install -y$missing"
    exit 1
fi
