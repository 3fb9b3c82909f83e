"""The LOD cache's CPU side (no GL): cameras for the 12 cached views and for the band, the atlas layout,
coverage-preserving mipmaps, the on-disk cache and the baking progress bar.

Section 5 of seeds/001: a cell's level-3 grass is rendered, at the 3→4 switch distance, into an RGBA image
with a transparent background, once every 30° (12 images).  Seen from the 3→4 distance a length L covers
P₃₄ pixels (eq. 1), so the capture resolution is P₃₄ / L texels per world unit whatever the window; the
rectangle showing an image is as large in the world as the region the image covers.  We capture with an
orthographic camera (an impostor is re-projected anyway) from elevation ``impostor_elevation_deg``.

Section 6: for the band, the far surroundings of a cell are captured in 12 directions (every 30°) from the
cell's centre with an off-axis perspective whose image plane is the band's side itself, so the captured
image maps linearly onto the band's rectangle.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from components.grass_field import GrassFieldConfig, GrassFieldState
from systems.grass_field.lod import N_BAND_SIDES, N_VIEWS

__all__ = ["impostor_basis", "TileFrame", "tile_frame", "tile_pixels", "tile_bounds", "AtlasLayout", "atlas_layout",
           "look_at", "perspective", "orthographic", "frustum", "bake_view_proj", "band_side_frame",
           "band_view_proj", "bake_depth_range", "coverage_mipmaps", "box_mipmaps", "cache_key", "DiskCache",
           "Progress", "CACHE_FORMAT"]

log = logging.getLogger("grass_field")
CACHE_FORMAT = 4  # 2: level-3 shading with the specular power as squarings (plant.frag); 3: with the depth image;
# 4: unlit (the albedo, and the normal beside the depth: impostor.frag lights each texel)
ATLAS_PAD = 4  # texels around each tile (mip levels up to 2 stay inside their tile)
ATLAS_MIP_LEVELS = 3


# ------------------------------------------------------------------------------------------- matrices
def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """4×4 world→camera matrix (camera looks down -z), column-vector convention."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:
        r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    return _camera(eye, r, u, -f)


def _camera(eye: np.ndarray, right: np.ndarray, up: np.ndarray, back: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = right, up, back
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection (``fov_y`` radians)."""
    f = 1.0 / np.tan(0.5 * fov_y)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """OpenGL off-axis perspective projection (glFrustum)."""
    m = np.zeros((4, 4))
    m[0, 0] = 2.0 * near / (right - left)
    m[1, 1] = 2.0 * near / (top - bottom)
    m[0, 2] = (right + left) / (right - left)
    m[1, 2] = (top + bottom) / (top - bottom)
    m[2, 2] = -(far + near) / (far - near)
    m[2, 3] = -2.0 * far * near / (far - near)
    m[3, 2] = -1.0
    return m


def orthographic(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """OpenGL orthographic projection (glOrtho)."""
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = 2.0 / (right - left), 2.0 / (top - bottom), -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


# ------------------------------------------------------------------------------------------ level 4
def impostor_basis(azimuth: float, elevation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, normal) of a rectangle facing azimuth ``azimuth`` from elevation ``elevation``.

    ``normal`` points from the cell towards the camera; a camera looking down ``-normal`` sees ``right`` to
    its right and ``up`` upwards.  ``shaders/common.glsl`` has the same function.
    """
    ca, sa, ce, se = np.cos(azimuth), np.sin(azimuth), np.cos(elevation), np.sin(elevation)
    right = np.array([sa, 0.0, -ca])
    up = np.array([-se * ca, ce, -se * sa])
    normal = np.array([ce * ca, se, ce * sa])
    return right, up, normal


@dataclass(frozen=True)
class TileFrame:
    """The region one cached image covers, in the rectangle's (right, up) frame around the cell's ground
    centre, plus the depth range and how far the rectangle is pushed towards the viewer."""

    half_width: float
    bottom: float
    top: float
    depth: float  # the cell's extent along the view normal (the rectangle is drawn this much nearer)
    elevation: float  # radians


def tile_frame(cell_size: float, reach: float, height: float, elevation: float) -> TileFrame:
    """Bounds over all 12 views of the box holding a cell's plants (the same tile size for every view)."""
    half = 0.5 * cell_size + reach
    corners = np.array([[x, y, z] for x in (-half, half) for y in (0.0, height) for z in (-half, half)])
    hw, lo, hi, depth = 0.0, np.inf, -np.inf, 0.0
    for k in range(N_VIEWS):
        right, up, normal = impostor_basis(k * 2.0 * np.pi / N_VIEWS, elevation)
        hw = max(hw, float(np.abs(corners @ right).max()))
        lo, hi = min(lo, float((corners @ up).min())), max(hi, float((corners @ up).max()))
        depth = max(depth, float(np.abs(corners @ normal).max()))
    return TileFrame(hw, lo, hi, depth, elevation)


def tile_pixels(frame: TileFrame, cfg: GrassFieldConfig) -> tuple[int, int]:
    """Tile size in texels: P₃₄ / L texels per unit (eq. 1 at the 3→4 distance), capped by impostor_max_size."""
    texels_per_unit = cfg.level_thresholds[3] / cfg.length_of_interest * cfg.impostor_resolution_scale
    w = 2.0 * frame.half_width * texels_per_unit
    h = (frame.top - frame.bottom) * texels_per_unit
    shrink = min(1.0, cfg.impostor_max_size / max(w, h))
    return max(8, int(np.ceil(w * shrink))), max(8, int(np.ceil(h * shrink)))


def tile_bounds(image: np.ndarray, layout: AtlasLayout, margin: int = 2 ** ATLAS_MIP_LEVELS,
                threshold: int = 1) -> np.ndarray:
    """(tiles, 4) the part of each tile holding grass, as fractions (u0, v0, u1, v1) of the tile.

    The rectangles are trimmed to it so the transparent rest of a tile costs no fill; ``margin`` texels are
    kept around it for the coarser mip levels.  An empty tile gets an empty rectangle.
    """
    out = np.zeros((layout.tiles, 4), dtype=np.float32)
    covered = image[..., 3] >= threshold
    for tile in range(layout.tiles):  # bake time only
        x, y, w, h = layout.viewport(tile)
        block = covered[y:y + h, x:x + w]
        cols, rows = np.flatnonzero(block.any(axis=0)), np.flatnonzero(block.any(axis=1))
        if len(cols) == 0:
            continue
        out[tile] = [max(cols[0] - margin, 0) / w, max(rows[0] - margin, 0) / h,
                     min(cols[-1] + 1 + margin, w) / w, min(rows[-1] + 1 + margin, h) / h]
    return out


def bake_depth_range(frame: TileFrame) -> tuple[float, float, float]:
    """(distance of the cached views' camera from the cell's centre, its near and far planes)."""
    distance = 2.0 * frame.depth + 1.0
    return distance, 0.5, distance + frame.depth + 1.0


def bake_view_proj(view: int, frame: TileFrame) -> np.ndarray:
    """World→clip of cached view ``view`` (azimuth view·30°) of a cell centred at the origin (ground y = 0):
    orthographic, from ``normal · distance`` looking down ``-normal`` (:func:`bake_depth_range`)."""
    right, up, normal = impostor_basis(view * 2.0 * np.pi / N_VIEWS, frame.elevation)
    distance, near, far = bake_depth_range(frame)
    v = _camera(normal * distance, right, up, normal)
    p = orthographic(-frame.half_width, frame.half_width, frame.bottom, frame.top, near, far)
    return p @ v


@dataclass(frozen=True)
class AtlasLayout:
    """Tiles of ``tile_w × tile_h`` texels on a grid, ``pad`` texels of transparent border around each."""

    tiles: int
    tile_w: int
    tile_h: int
    cols: int
    rows: int
    pad: int = ATLAS_PAD

    @property
    def size(self) -> tuple[int, int]:
        return self.cols * (self.tile_w + 2 * self.pad), self.rows * (self.tile_h + 2 * self.pad)

    def viewport(self, tile: int) -> tuple[int, int, int, int]:
        """(x, y, w, h) of ``tile`` in texels (y up, as glViewport)."""
        col, row = tile % self.cols, tile // self.cols
        return (col * (self.tile_w + 2 * self.pad) + self.pad, row * (self.tile_h + 2 * self.pad) + self.pad,
                self.tile_w, self.tile_h)


def atlas_layout(tiles: int, tile_w: int, tile_h: int, max_size: int, pad: int = ATLAS_PAD) -> AtlasLayout:
    """A roughly square grid of tiles; tiles shrink (keeping their aspect) until it fits ``max_size``."""
    while True:
        cw, ch = tile_w + 2 * pad, tile_h + 2 * pad
        cols = max(1, min(tiles, int(np.ceil(np.sqrt(tiles * ch / cw)))))
        rows = int(np.ceil(tiles / cols))
        if cols * cw <= max_size and rows * ch <= max_size:
            return AtlasLayout(tiles, tile_w, tile_h, cols, rows, pad)
        if tile_w <= 8 and tile_h <= 8:
            raise ValueError(f"{tiles} cached images do not fit a {max_size}² texture; "
                             "lower cell_variants")
        tile_w, tile_h = max(8, int(tile_w * 0.85)), max(8, int(tile_h * 0.85))


def coverage_mipmaps(image: np.ndarray, levels: int = ATLAS_MIP_LEVELS, threshold: float = 0.5) -> list[np.ndarray]:
    """Mip levels 1..``levels`` of a premultiplied RGBA8 image whose alpha is tested against ``threshold``.

    Box-filtered in premultiplied form, then each level's alpha (and colour) is scaled so the fraction of
    texels passing the alpha test equals level 0's (coverage-preserving mipmaps): thin grass does not thin
    out with distance.  The boxes are exact integer sums (a level-k texel is the sum of 4^k texels over
    255 · 4^k), so the alphas a level can hold are counted in a histogram instead of sorted: about 9 times
    faster than float boxes and a sort on a 2048² atlas, with the same bytes.
    """
    coverage = float(np.mean(image[..., 3] / 255.0 >= threshold))
    sums = image.astype(np.uint32)
    out = []
    for k in range(1, levels + 1):
        h, w = sums.shape[0] // 2, sums.shape[1] // 2
        if h < 1 or w < 1:
            break
        s = sums[:2 * h, :2 * w]
        sums = s[0::2, 0::2] + s[1::2, 0::2] + s[0::2, 1::2] + s[1::2, 1::2]
        full = 255 * 4 ** k  # an opaque texel's sum
        level = sums * (1.0 / full)
        if 0.0 < coverage < 1.0:
            scale = _coverage_scale(sums[..., 3], full, coverage, threshold)
            if scale is not None:
                level = np.clip(level * scale, 0.0, 1.0)
                level[..., :3] = np.minimum(level[..., :3], level[..., 3:4])
        out.append(np.round(level * 255.0).astype(np.uint8))
    return out


def box_mipmaps(image: np.ndarray, levels: int = ATLAS_MIP_LEVELS) -> list[np.ndarray]:
    """Mip levels 1..``levels`` of ``image`` (h, w, channels) as plain means of 2 × 2 texels, over the same texels
    as :func:`coverage_mipmaps` (an odd last row or column left out, as GL sizes a level): the atlas's depth image
    (depth · coverage, coverage), whose levels must have coverage wherever the colour's pass the alpha test.
    float32 (the caller converts)."""
    out, current = [], np.asarray(image, np.float32)
    for _ in range(levels):
        h, w = current.shape[0] // 2, current.shape[1] // 2
        if h < 1 or w < 1:
            break
        c = current[:2 * h, :2 * w]
        current = (c[0::2, 0::2] + c[1::2, 0::2] + c[0::2, 1::2] + c[1::2, 1::2]) * np.float32(0.25)
        out.append(current)
    return out


def _coverage_scale(alpha_sums: np.ndarray, full: int, coverage: float, threshold: float) -> float | None:
    """The alpha scale whose alpha test passes the fraction of texels closest to ``coverage`` (the smallest such
    alpha on a tie); ``alpha_sums`` are integer box sums out of ``full``."""
    counts = np.bincount(alpha_sums.ravel(), minlength=full + 1)
    candidates = np.flatnonzero(counts[1:]) + 1  # the alphas present, above zero, ascending
    if len(candidates) == 0:
        return None
    passing = np.cumsum(counts[::-1])[::-1] / alpha_sums.size  # the fraction of texels at or above each alpha
    best = candidates[int(np.argmin(np.abs(passing[candidates] - coverage)))]
    return (threshold + 0.5 / 255.0) / (best / full)  # lands the chosen texels safely above the 8-bit threshold


# ------------------------------------------------------------------------------------------ level 5
def band_side_frame(centre: np.ndarray, apothem: float, side: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(outward normal, right vector, half width) of band side ``side`` around ``centre`` (3,)."""
    a = side * 2.0 * np.pi / N_BAND_SIDES
    normal = np.array([np.cos(a), 0.0, np.sin(a)])
    right = np.array([-np.sin(a), 0.0, np.cos(a)])
    return normal, right, apothem * np.tan(np.pi / N_BAND_SIDES)


def band_view_proj(eye: np.ndarray, apothem: float, side: int, bottom: float, top: float,
                   far: float) -> np.ndarray:
    """World→clip of the camera capturing band side ``side`` from ``eye``: an off-axis perspective whose
    image plane is the side's rectangle (x across the side, y from ``bottom`` to ``top`` world heights)."""
    normal, right, half = band_side_frame(eye, apothem, side)
    v = _camera(np.asarray(eye, dtype=np.float64), right, np.array([0.0, 1.0, 0.0]), -normal)
    near = 0.25 * apothem
    s = near / apothem
    p = frustum(-half * s, half * s, (bottom - eye[1]) * s, (top - eye[1]) * s, near, max(far, 2.0 * apothem))
    return p @ v


# ------------------------------------------------------------------------------------------ disk cache
_IMAGE_INDEPENDENT = {"max_level", "debug_levels", "disk_cache", "cache_dir", "face_turn_deg", "image_switch_deg",
                      "blend_views", "near_cull_cells", "merge_distance", "band_resolution_scale",
                      "band_cache_cells", "grid_x", "grid_z", "bare_areas"}


def cache_key(cfg: GrassFieldConfig, state: GrassFieldState, extra: dict) -> str:
    """SHA-256 of the canonical JSON of what the cached images depend on.

    That is the config (minus the keys that only steer selection or display), the random layouts and plant
    shapes drawn from the seed (as a digest), and ``extra`` (lighting, tile size, format version).
    """
    config = {k: v for k, v in cfg.model_dump(mode="json", warnings=False).items() if k not in _IMAGE_INDEPENDENT}
    h = hashlib.sha256()
    for name in ("variant_branch_count", "variant_segments", "variant_base_length", "variant_tilt",
                 "variant_azimuth", "layout_offset", "layout_yaw", "layout_variant", "layout_scale", "layout_tint"):
        arr = np.ascontiguousarray(getattr(state, name))
        h.update(f"{name}:{arr.dtype.str}:{arr.shape}|".encode())
        h.update(arr.tobytes())
    payload = {"format": CACHE_FORMAT, "config": config, "draws": h.hexdigest(), "extra": extra}
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class DiskCache:
    """Baked atlases stored as ``<dir>/grass_field_<key>.npz``; written atomically, ignored when unreadable."""

    def __init__(self, directory: str | os.PathLike) -> None:
        self.directory = Path(directory)

    def path(self, key: str) -> Path:
        return self.directory / f"grass_field_{key[:40]}.npz"

    def load(self, key: str, shape: tuple[int, int, int], depth_shape: tuple[int, int, int],
             normal_shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(the colour atlas, uint8 ``shape``; its depth image, float16 ``depth_shape``; its normal image, uint8
        ``normal_shape``), or None when the file is missing, unreadable or holds other shapes."""
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            with np.load(path) as data:
                found = [data[name] if name in data.files else None for name in ("atlas", "depth", "normal")]
                stored = str(data["key"])
        except (OSError, ValueError, KeyError) as exc:
            log.warning("grass_field: ignoring unreadable cache %s (%s)", path, exc)
            return None
        if stored != key:
            return None
        for array, want, dtype in zip(found, (shape, depth_shape, normal_shape), (np.uint8, np.float16, np.uint8)):
            if array is None or array.shape != want or array.dtype != dtype:
                return None  # stored without it (an older format) or for another layout: bake again
        atlas, depth, normal = found
        return atlas, depth, normal

    def store(self, key: str, atlas: np.ndarray, depth: np.ndarray, normal: np.ndarray) -> Path:
        self.directory.mkdir(parents=True, exist_ok=True)
        path = self.path(key)
        tmp = path.with_suffix(f".tmp{os.getpid()}.npz")
        np.savez_compressed(tmp, atlas=atlas, depth=depth, normal=normal, key=np.array(key))
        os.replace(tmp, path)
        return path


class Progress:
    """A text progress bar on stderr, shown only once the work has taken longer than ``after`` seconds."""

    def __init__(self, label: str, total: int, after: float = 0.5, stream=None, clock=time.perf_counter) -> None:
        self.label, self.total, self.after = label, max(1, int(total)), after
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self.start = clock()
        self.shown = False
        self.lines = 0

    def update(self, done: int) -> None:
        if not self.shown and self.clock() - self.start < self.after:
            return
        self.shown = True
        frac = min(1.0, done / self.total)
        bar = "#" * int(round(30 * frac))
        self.stream.write(f"\r{self.label} [{bar:<30}] {done}/{self.total}")
        self.lines += 1
        if done >= self.total:
            self.stream.write(f" ({self.clock() - self.start:.1f} s)\n")
        self.stream.flush()
