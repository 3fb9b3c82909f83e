#!/bin/sh
# Mesa's EGL and software rasteriser (llvmpipe) are needed for headless rendering and the render tests;
# Xvfb runs the window tests (a real pyglet window on a virtual screen).
missing=""
for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri xvfb; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing="$missing $pkg"
done
[ -z "$missing" ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
    echo "note: system packages not found ($missing); install your distribution's EGL, Mesa DRI and Xvfb packages."
    exit 0
fi
if [ "$(id -u)" = "0" ]; then
    echo "installing system packages for headless OpenGL and window tests:$missing"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing
else
    echo "Headless OpenGL and the window tests need:$missing"
    echo "Run: sudo apt-get install -y$missing"
    exit 1
fi
