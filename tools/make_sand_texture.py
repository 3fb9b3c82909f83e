"""Writes configs/assets/sand.png, the dust devil desert's ground texture (seeds/004 section 3.1: the terrain is
drawn "with a sand texture"); reproducible (seed fixed), 256 x 256 sRGB, seamless when tiled.

Three layers, every one periodic over the tile so that the repeats join without a seam:
* small patches of lighter and darker sand: value noise on 8- to 32-cell lattices that wrap around the tile
  (nothing larger, so the repeats do not show as a grid: large-scale variation comes from the terrain's ramp);
* wind ripples: a sine along an integer wave vector (so a whole number of crests fits the tile either way), its
  phase bent by the same kind of noise so the crests meander, crests lighter than troughs;
* grain: per-pixel noise of a few percent.
The terrain's `texture_size` says how many metres one tile covers (16 m in `terrain/dust_devil_desert`: ripples
about 0.7 m apart, large enough to survive the distance the paper's views are seen from).
"""

from pathlib import Path

import numpy as np
from PIL import Image

SIZE = 256
SEED = 4
RIPPLE_WAVE = (19, 7)  # crests per tile along x and y: integers, so the ripples tile
DARK, LIGHT = np.array([150.0, 116.0, 78.0]), np.array([222.0, 192.0, 146.0])  # sRGB of troughs/shade and crests


def periodic_noise(rng: np.random.Generator, cells: int) -> np.ndarray:
    """Smooth value noise in [0, 1] on a ``cells`` x ``cells`` lattice that wraps around the tile."""
    lattice = rng.random((cells, cells))
    t = np.arange(SIZE) * cells / SIZE
    i = np.floor(t).astype(int)
    f = t - i
    f = f * f * (3.0 - 2.0 * f)  # smoothstep between lattice points
    i0, i1 = i % cells, (i + 1) % cells
    rows = lattice[i0] * (1 - f)[:, None] + lattice[i1] * f[:, None]  # along y (rows)
    return rows[:, i0] * (1 - f)[None, :] + rows[:, i1] * f[None, :]


def sand() -> np.ndarray:
    rng = np.random.default_rng(SEED)
    patches = sum(w * periodic_noise(rng, c) for w, c in ((0.4, 8), (0.35, 16), (0.25, 32)))
    bend = periodic_noise(rng, 4) * 2.0 + periodic_noise(rng, 8) * 0.7
    y, x = np.mgrid[0:SIZE, 0:SIZE] / SIZE
    phase = 2.0 * np.pi * (RIPPLE_WAVE[0] * x + RIPPLE_WAVE[1] * y) + 2.0 * np.pi * bend
    ripple = np.sin(phase)
    ripple = np.sign(ripple) * np.abs(ripple) ** 0.6  # sharper crests
    tone = 0.5 + 0.35 * (patches - 0.5) + 0.12 * ripple + 0.05 * rng.standard_normal((SIZE, SIZE))
    tone = np.clip(tone, 0.0, 1.0)[..., None]
    return DARK + (LIGHT - DARK) * tone


def main() -> None:
    out = Path(__file__).resolve().parents[1] / "configs" / "assets" / "sand.png"
    Image.fromarray(np.round(sand()).astype(np.uint8)).save(out, optimize=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
