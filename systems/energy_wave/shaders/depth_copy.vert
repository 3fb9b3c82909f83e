#include "fullscreen.vert"
