"""Writes configs/assets/valley.png, the demo's 129x129 16-bit height map (reproducible; seed fixed).

Heights, before the Terrain's height_scale (29 m for white) and the entity's -4 m offset:
a valley floor about 0.5-1.5 m above the water line, a pond basin about 3 m deep centred on
(POND_X, POND_Z), and rims rising to about 25 m at the edges.  Spacing in the scene is 1.5 m.
"""

from pathlib import Path

import numpy as np
from PIL import Image

from engine.noise import PerlinNoise

N, SPACING, SCALE, OFFSET = 129, 1.5, 29.0, -4.0
POND_X, POND_Z, POND_R = 24.0, 22.0, 9.0


def heights() -> np.ndarray:
    c = (np.arange(N) - (N - 1) / 2) * SPACING
    x, z = np.meshgrid(c, c)  # rows = z, columns = x
    r = np.hypot(x, z) / (c[-1])
    rim = 26.0 * np.clip((r - 0.55) / 0.45, 0.0, 1.0) ** 2
    noise = PerlinNoise(11)
    floor = 1.0 + 0.7 * noise.fbm2(x / 18.0, z / 18.0, octaves=4) + 2.5 * noise.fbm2(x / 40.0 + 5, z / 40.0, octaves=2) * (r > 0.5)
    pond = 3.8 * np.exp(-((x - POND_X) ** 2 + (z - POND_Z) ** 2) / (2 * POND_R ** 2))
    return floor + rim - pond


def main() -> None:
    h = heights()
    stored = np.clip((h - OFFSET) / SCALE, 0.0, 1.0)
    out = Path(__file__).resolve().parents[1] / "configs" / "assets" / "valley.png"
    Image.fromarray((stored * 65535).round().astype(np.uint16)).save(out)
    print(f"wrote {out}: heights {h.min():.2f} .. {h.max():.2f} m")


if __name__ == "__main__":
    main()
