"""Quaternion helpers and the runtime ``Transform``.

Conventions: quaternions are float64 arrays in (w, x, y, z) order; every helper accepts a single quaternion
(4,) or a stack (..., 4) and broadcasts. Space is right-handed with +Y up; a camera or entity looks down its
local -Z axis, +X is its right. Rotations act on column vectors (``R @ v``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine import exact

__all__ = [
    "Transform",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_from_euler",
    "quat_identity",
    "quat_is_identity",
    "quat_mul",
    "quat_normalize",
    "quat_rotate",
    "quat_to_matrix",
]

F64 = NDArray[np.float64]


def quat_identity() -> F64:
    """The identity rotation (1, 0, 0, 0)."""
    return np.array([1.0, 0.0, 0.0, 0.0])


def quat_is_identity(q: ArrayLike) -> bool:
    """Whether q is exactly (1, 0, 0, 0): a rotation that returns its input (callers skip rotating then)."""
    return bool(q[0] == 1.0 and q[1] == 0.0 and q[2] == 0.0 and q[3] == 0.0)


def quat_normalize(q: ArrayLike) -> F64:
    """Unit quaternion q / |q|; raises ``ValueError`` for a zero quaternion."""
    q = np.asarray(q, dtype=np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError("cannot normalize a zero quaternion (0, 0, 0, 0)")
    return q / norm


def quat_from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> F64:
    """Rotation by ``angle`` radians about ``axis`` (right-hand rule): q = (cos(θ/2), sin(θ/2)·â)."""
    axis = np.asarray(axis, dtype=np.float64)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError(f"rotation axis must be non-zero, got {axis.tolist()}")
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    vector = exact.sin(half) * axis / norm
    return np.concatenate([np.broadcast_to(exact.cos(half), vector.shape[:-1] + (1,)), vector], axis=-1)


def quat_mul(a: ArrayLike, b: ArrayLike) -> F64:
    """Hamilton product a ⊗ b: the rotation that applies ``b`` first, then ``a``."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_from_euler(yaw: float, pitch: float, roll: float) -> F64:
    """Rotation from Euler angles in radians, y up, right-handed, applied roll → pitch → yaw.

    ``q = q_yaw(+Y) ⊗ q_pitch(+X) ⊗ q_roll(+Z)`` (intrinsic Y-X'-Z''). With the forward axis -Z: positive yaw
    turns forward towards -X (left, counter-clockwise seen from above), positive pitch tilts it up towards +Y,
    positive roll turns +X (right) towards +Y.
    """
    if np.ndim(yaw) == 0 and np.ndim(pitch) == 0 and np.ndim(roll) == 0:
        return _euler_scalar(float(yaw), float(pitch), float(roll))
    q_yaw = quat_from_axis_angle((0.0, 1.0, 0.0), yaw)
    q_pitch = quat_from_axis_angle((1.0, 0.0, 0.0), pitch)
    q_roll = quat_from_axis_angle((0.0, 0.0, 1.0), roll)
    return quat_mul(q_yaw, quat_mul(q_pitch, q_roll))


def _axis_scalar(angle: float, axis: tuple[float, float, float]) -> tuple[float, float, float, float]:
    """:func:`quat_from_axis_angle` of one unit coordinate axis, in the same operations (sin and cos by numpy,
    the products and the division by the norm 1 as written there, zero components keeping their sign)."""
    half = np.float64(0.5 * angle)
    s, c = exact.sin_scalar(half), exact.cos_scalar(half)
    return c, s * axis[0] / 1.0, s * axis[1] / 1.0, s * axis[2] / 1.0


def _mul_scalar(a: tuple, b: tuple) -> tuple[float, float, float, float]:
    """:func:`quat_mul` of two quaternions as Python floats, term by term in its order (IEEE doubles: the same
    bits as numpy's element-wise arithmetic)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _euler_scalar(yaw: float, pitch: float, roll: float) -> F64:
    """:func:`quat_from_euler` for single angles without numpy's per-call array overhead (~50x faster; scripts
    and cameras call it every tick), bit for bit the array path's result."""
    q_yaw = _axis_scalar(yaw, (0.0, 1.0, 0.0))
    q_pitch = _axis_scalar(pitch, (1.0, 0.0, 0.0))
    q_roll = _axis_scalar(roll, (0.0, 0.0, 1.0))
    return np.array(_mul_scalar(q_yaw, _mul_scalar(q_pitch, q_roll)))


def quat_conjugate(q: ArrayLike) -> F64:
    """(w, -x, -y, -z): the inverse rotation of a unit quaternion."""
    q = np.array(q, dtype=np.float64)
    q[..., 1:] *= -1.0
    return q


def quat_rotate(q: ArrayLike, v: ArrayLike) -> F64:
    """Rotate vectors ``v`` (..., 3) by unit quaternion(s) ``q``: v' = v + 2u×(u×v + w·v), u = (x, y, z).

    This is q v q* expanded without forming the product; ``q`` broadcasts against ``v`` (one q for (N, 3)
    points, or one q per point).
    """
    q, v = np.asarray(q, dtype=np.float64), np.asarray(v, dtype=np.float64)
    w, u = q[..., :1], q[..., 1:]
    return v + 2.0 * cross(u, cross(u, v) + w * v)


def cross(a: ArrayLike, b: ArrayLike) -> F64:
    """a × b over the last axis, the same products and differences as ``np.cross`` (so the same bits) without
    its axis bookkeeping, which dominates for the few vectors that scripts and colliders rotate per call."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def quat_to_matrix(q: ArrayLike) -> F64:
    """3×3 rotation matrix (column-vector convention) of q, with s = 2/|q|² so non-unit q still give a rotation.

    Vectorised over leading axes: (..., 4) -> (..., 3, 3), written entry by entry into one array. One
    quaternion (4,) takes :func:`_matrix_scalar` (the same bits).
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape == (4,):
        m = _matrix_scalar(*q.tolist())
        if m is not None:
            return m
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / (w * w + x * x + y * y + z * z)
    xs, ys, zs = x * s, y * s, z * s
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1.0 - (y * ys + z * zs)
    m[..., 0, 1] = x * ys - w * zs
    m[..., 0, 2] = x * zs + w * ys
    m[..., 1, 0] = x * ys + w * zs
    m[..., 1, 1] = 1.0 - (x * xs + z * zs)
    m[..., 1, 2] = y * zs - w * xs
    m[..., 2, 0] = x * zs - w * ys
    m[..., 2, 1] = y * zs + w * xs
    m[..., 2, 2] = 1.0 - (x * xs + y * ys)
    return m


def _matrix_scalar(w: float, x: float, y: float, z: float) -> F64 | None:
    """:func:`quat_to_matrix` of one quaternion as Python floats, entry by entry in its order (IEEE doubles: the
    same bits as numpy's element-wise arithmetic) without numpy's per-call overhead on 0-d arrays (about ten times
    faster; the energy wave's sweep bounds a turning crate's box with it every tick). None for q = 0, where
    Python's division raises and numpy's gives inf with a warning: the array path keeps that case."""
    norm2 = w * w + x * x + y * y + z * z
    if norm2 == 0.0:
        return None
    s = 2.0 / norm2
    xs, ys, zs = x * s, y * s, z * s
    return np.array([[1.0 - (y * ys + z * zs), x * ys - w * zs, x * zs + w * ys],
                     [x * ys + w * zs, 1.0 - (x * xs + z * zs), y * zs - w * xs],
                     [x * zs - w * ys, y * zs + w * xs, 1.0 - (x * xs + y * ys)]])


def model_matrices(positions: ArrayLike, rotations: ArrayLike, scales: ArrayLike) -> F64:
    """Batched T·R·S model matrices (N, 4, 4) from positions (N, 3), quaternions (N, 4) and scales (N, 3)."""
    positions = np.asarray(positions, dtype=np.float64)
    m = np.zeros(positions.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(rotations) * np.asarray(scales, dtype=np.float64)[..., None, :]
    m[..., :3, 3] = positions
    m[..., 3, 3] = 1.0
    return m


def _vec3(value: ArrayLike, name: str) -> F64:
    array = np.array(value, dtype=np.float64)
    if array.shape != (3,):
        raise ValueError(f"Transform.{name} must have shape (3,), got {array.shape}: {array.tolist()}")
    return array


@dataclass
class Transform:
    """Position, rotation (unit quaternion w, x, y, z) and per-axis scale of an entity, all float64.

    ``to_world(p) = position + R · (scale * p)``; the matrix is T·R·S for column vectors, i.e.
    ``matrix() @ [x, y, z, 1]``.
    """

    position: F64 = field(default_factory=lambda: np.zeros(3))
    rotation: F64 = field(default_factory=quat_identity)
    scale: F64 = field(default_factory=lambda: np.ones(3))

    def __post_init__(self) -> None:
        self.position = _vec3(self.position, "position")
        self.scale = _vec3(self.scale, "scale")
        rotation = np.array(self.rotation, dtype=np.float64)
        if rotation.shape != (4,):
            raise ValueError(f"Transform.rotation must be a (w, x, y, z) quaternion, got shape {rotation.shape}")
        self.rotation = rotation

    def rotation_matrix(self) -> F64:
        """3×3 rotation R of ``rotation``."""
        return quat_to_matrix(self.rotation)

    def matrix(self) -> F64:
        """4×4 model matrix T·R·S (column vectors: world = M @ [x, y, z, 1])."""
        m = np.eye(4)
        m[:3, :3] = self.rotation_matrix() * self.scale[None, :]
        m[:3, 3] = self.position
        return m

    def forward(self) -> F64:
        """World direction of the local -Z axis (where the entity looks), unit length."""
        return quat_rotate(self.rotation, np.array([0.0, 0.0, -1.0]))

    def right(self) -> F64:
        """World direction of the local +X axis, unit length."""
        return quat_rotate(self.rotation, np.array([1.0, 0.0, 0.0]))

    def up(self) -> F64:
        """World direction of the local +Y axis, unit length."""
        return quat_rotate(self.rotation, np.array([0.0, 1.0, 0.0]))

    def to_world(self, points: ArrayLike) -> F64:
        """Local points (N, 3) to world: position + R · (scale * p)."""
        points = np.asarray(points, dtype=np.float64)
        return self.position + quat_rotate(self.rotation, points * self.scale)

    def to_local(self, points: ArrayLike) -> F64:
        """World points (N, 3) to local: R⁻¹ · (p - position) / scale (inverse of :meth:`to_world`)."""
        points = np.asarray(points, dtype=np.float64)
        return quat_rotate(quat_conjugate(self.rotation), points - self.position) / self.scale
