"""Compiled kernels (``engine.jit.kernel``) for the floating rigid bodies of ``bodies.py``: one call advances the
bodies of one water by a fixed step (every sub-step's buoyancy, drag, speed limits, Euler's equations and
quaternion update), then resolves their contacts with the pool and limits their speeds again.

``bodies.integrate_numpy`` and the functions it calls (``water_forces``, ``pool_contacts``, ``_limit``) are the
readable statement of the method and the reference: this kernel does their IEEE operations in their order, so every
output has the same bits (``tests/systems/water_surface/test_body_kernels.py``). In numpy the step of a few bodies
is some 200 calls on arrays of a few elements, bound by the cost of a call. Repeating numpy's order takes:

- a sum over an array's last axis is numpy's pairwise summation (``engine.jit.pairwise_sum``) added to 0.0, the
  reduction's start, so a sum of −0.0 is +0.0; a sum along another axis adds in index order from 0.0;
- ``engine.exact``'s products add their terms left to right, every product written out, even by a constant 0
  (0·x is −0.0 or NaN for some x), and the quaternion rate keeps (0, ω)'s zero;
- ``np.einsum`` of the pool corners' rotation (3 terms) adds them in the order of the loop numpy picks from the
  matrices' memory layout: in index order, or, for a group of one body (whose matrix rows are contiguous), as its
  two-lane SIMD loop does, (t0 + t2) + t1 (see :func:`_contact_points`);
- ``np.maximum``/``np.minimum`` give NaN if either value is NaN and the second value on a tie (±0);
- the damping's exponentials come from numpy (the caller's ``np.exp``) and r³ from numpy's power; the kernel
  calls no transcendental function (``sqrt`` is correctly rounded everywhere).

With ``NUMBA_DISABLE_JIT=1`` the same code runs as Python on numpy scalars, with the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from engine.jit import kernel, maximum, minimum, pairwise_sum

BOX, SPHERE = 0, 1  # geometry.BOX / SPHERE
OMEGA_DT = 0.3  # bodies._OMEGA_DT
SPHERE_VOLUME = 4.0 / 3.0 * np.pi  # the factor of r³ in BodyArrays.volume, as Python computes it
POSITION, ROTATION, VELOCITY, SPIN = 0, 3, 7, 10  # columns of the state (B, 13)
SUMS = 8  # sums per body over its samples: V, V·w, F (3), τ (3)


@kernel
def _sum3(a, b, c):
    """np.add.reduce of three values along the last axis: 0.0 + (((0.0 + a) + b) + c)."""
    return 0.0 + (((0.0 + a) + b) + c)


@kernel
def _limit(state, b, column, limit):
    """bodies._limit of the row state[b, column:column + 3] (in place): scaled down to ``limit`` when longer,
    zero when a component is not finite, a row too long to square scaled by its largest component first."""
    x, y, z = state[b, column], state[b, column + 1], state[b, column + 2]
    if x * x + y * y + z * z <= limit * limit:
        return
    if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
        big = maximum(maximum(abs(x), abs(y)), abs(z))
        ux, uy, uz = x / big, y / big, z / big
        scale = limit / (big * math.sqrt(ux * ux + uy * uy + uz * uz))
        state[b, column], state[b, column + 1], state[b, column + 2] = x * scale, y * scale, z * scale
    else:
        state[b, column], state[b, column + 1], state[b, column + 2] = 0.0, 0.0, 0.0


@kernel
def _rotation(state, b, terms, rot):
    """bodies.quat_to_matrix of body b's quaternion into ``rot`` (3, 3): (q_a·q_b·(±2) + q_c·q_d·(±2)) + δ."""
    for e in range(9):
        first = (state[b, ROTATION + terms[e, 1]] * state[b, ROTATION + terms[e, 2]]) * (2.0 * terms[e, 0])
        second = (state[b, ROTATION + terms[e, 4]] * state[b, ROTATION + terms[e, 5]]) * (2.0 * terms[e, 3])
        rot[e // 3, e % 3] = (first + second) + (1.0 if e % 4 == 0 else 0.0)


@kernel
def _moments(shapes, half, radius, mass, b, out):
    """bodies.inertia of body b into ``out`` (3,): box m/12·(b² + c², …) with full sizes, sphere 2/5·m·r²."""
    if shapes[b] == SPHERE:
        sphere = (0.4 * mass[b]) * (radius[b] * radius[b])
        out[0], out[1], out[2] = sphere, sphere, sphere
    else:
        f0, f1, f2 = 2.0 * half[b, 0], 2.0 * half[b, 1], 2.0 * half[b, 2]
        f0, f1, f2 = f0 * f0, f1 * f1, f2 * f2
        m12 = mass[b] / 12.0
        out[0], out[1], out[2] = m12 * (f1 + f2), m12 * (f0 + f2), m12 * (f0 + f1)


@kernel
def substep_rate(shapes, half, radius, mass, gravity, density, dt):
    """max ω·Δt / 0.3 over the bodies, ω = √(ρ·g·A/m): ``bodies.substeps`` before its ceil, the same bits (NaN
    if any ω is)."""
    top = 0.0
    for b in range(len(mass)):
        h0, h1, h2 = half[b, 0], half[b, 1], half[b, 2]
        faces = 4.0 * maximum(maximum(h0 * h1, h1 * h2), h0 * h2)
        area = np.pi * (radius[b] * radius[b]) if shapes[b] == SPHERE else faces
        omega = math.sqrt(density * maximum(gravity[b], 1e-9) * area / mass[b])
        top = omega if b == 0 else maximum(top, omega)
    return top * dt / OMEGA_DT


@kernel
def _water_forces(state, b, rot, shapes, half, radius, volume, gravity, samples, count, heights, previous, gx, gz,
                  nx, nz, x0, z0, gh, y0, dt, density, scratch, out):
    """bodies.water_forces of body b: ``out`` = (submerged volume, mean vertical water velocity, force (3), torque
    (3)). Per sample (``bodies._samples``: a box's lattice turned with it, a sphere's columns) the submerged share
    of its volume from the bilinear water height at t and its slope, and the height at t − 1
    (``geometry.bilinear_slope_pair`` on the flat ``heights``/``previous`` of ``gz`` rows of ``gx``); the sums are
    numpy's pairwise ones over the ``count`` samples."""
    box = shapes[b] != SPHERE
    thickness = 0.0
    if box:
        thickness = _sum3(abs(rot[1, 0]) * half[b, 0], abs(rot[1, 1]) * half[b, 1], abs(rot[1, 2]) * half[b, 2]) * 0.5
    px, py, pz = state[b, POSITION], state[b, POSITION + 1], state[b, POSITION + 2]
    rho_g = density * gravity[b]
    for k in range(count):
        if box:
            l0, l1, l2 = samples[0, k] * half[b, 0], samples[1, k] * half[b, 1], samples[2, k] * half[b, 2]
            ox = (rot[0, 0] * l0 + rot[0, 1] * l1) + rot[0, 2] * l2
            oy = (rot[1, 0] * l0 + rot[1, 1] * l1) + rot[1, 2] * l2
            oz = (rot[2, 0] * l0 + rot[2, 1] * l1) + rot[2, 2] * l2
            dv = volume * samples[6, k]
            s = thickness
        else:
            ox, oy, oz = samples[3, k] * radius[b], samples[4, k] * radius[b], samples[5, k] * radius[b]
            dv = volume * samples[7, k]
            s = samples[8, k] * radius[b]
        y = py + oy
        u = (px + ox - x0) / gh
        v = (pz + oz - z0) / gh
        wet = u >= 0.0 and u <= nx - 1 and v >= 0.0 and v <= nz - 1
        cu = minimum(maximum(u, 0.0), float(gx - 1))
        cv = minimum(maximum(v, 0.0), float(gz - 1))
        if cu != cu or cv != cv:  # numpy's lookup fails here too (an index out of bounds)
            raise ValueError("a floating body's position is not a number")
        i = min(int(cu), gx - 2)
        j = min(int(cv), gz - 2)
        tu, tv = cu - i, cv - j
        c = j * gx + i
        z00, z10, z01, z11 = heights[c], heights[c + 1], heights[c + gx], heights[c + gx + 1]
        bottom = z00 + tu * (z10 - z00)
        top = z01 + tu * (z11 - z01)
        du = (1.0 - tv) * (z10 - z00) + tv * (z11 - z01)
        eta = bottom + tv * (top - bottom)
        dz = top - bottom
        o00, o10, o01, o11 = previous[c], previous[c + 1], previous[c + gx], previous[c + gx + 1]
        o_bottom = o00 + tu * (o10 - o00)
        o_top = o01 + tu * (o11 - o01)
        before = o_bottom + tv * (o_top - o_bottom)
        frac = minimum(maximum((y0 + eta - y) / s + 0.5, 0.0), 1.0) * (1.0 if wet else 0.0)
        sub = frac * dv
        push = rho_g * sub
        fx, fz = push * du / -gh, push * dz / -gh
        scratch[0, k] = sub
        scratch[1, k] = sub * ((eta - before) / dt)
        scratch[2, k], scratch[3, k], scratch[4, k] = fx, push, fz
        scratch[5, k] = oy * fz - oz * push
        scratch[6, k] = oz * fx - ox * fz
        scratch[7, k] = ox * push - oy * fx
    for r in range(SUMS):
        out[r] = 0.0 + pairwise_sum(scratch[r], 0, count)
    submerged = out[0]
    out[1] = out[1] / (submerged if submerged > 0.0 else 1.0)
    if not box:  # pressure on a sphere acts through its centre
        out[5], out[6], out[7] = 0.0, 0.0, 0.0


@kernel
def float_bodies(state, submerged, shapes, half, radius, cube, mass, gravity, force, torque, decay_v, decay_w,
                 max_speed, max_spin, restitution, friction, steps, h, dt, in_water, heights, previous, nx, nz, x0, z0,
                 gh, y0, linear_drag, angular_drag, density, floor, contacts, samples, box_samples, terms, planes,
                 corners):
    """``bodies.integrate_numpy`` of B bodies, ``steps`` sub-steps of ``h``, then (``contacts``) ``pool_contacts``
    and ``limit_speeds``: the same bits.

    ``state`` (B, 13): positions, quaternions (w, x, y, z), velocities, spins; updated in place. ``submerged`` (B,)
    receives the last sub-step's submerged volumes (left as given out of the water). ``cube`` = radius³ (``bodies.cube``),
    ``decay_v``/``decay_w`` = exp(−damping·h) (``engine.exact.exp``). ``in_water``: ``heights``/``previous``
    (nz, nx) z(t) and z(t − 1) of a grid of ``nx`` × ``nz`` vertices, spacing ``gh``, P[0, 0] at (x0, z0), rest level
    ``y0``; ``floor`` the pool's floor. ``samples`` (9, S): the box lattice and sphere columns (coordinate-major,
    in half extents / radii), their shares of the volume, the columns' chords; ``box_samples`` the lattice's size
    (all-box groups sum over it, mixed ones over S). ``terms``: kernels.QUAT_TERMS; ``planes`` (5, 3) the pool's
    inward normals (floor, walls); ``corners`` (8, 3) a box's corners in half extents.
    """
    n = len(mass)
    all_box = True
    for b in range(n):
        if shapes[b] == SPHERE:
            all_box = False
    count = box_samples if all_box else samples.shape[1]
    gz, gx = heights.shape
    flat, flat_previous = heights.ravel(), previous.ravel()
    rot = np.empty((3, 3))
    moments = np.empty(3)
    sums = np.empty(SUMS)
    scratch = np.empty((SUMS, samples.shape[1]))
    for b in range(n):
        _moments(shapes, half, radius, mass, b, moments)
        m0, m1, m2 = moments[0], moments[1], moments[2]
        if shapes[b] == SPHERE:
            volume = SPHERE_VOLUME * cube[b]
        else:
            volume = 8.0 * ((half[b, 0] * half[b, 1]) * half[b, 2])
        m = mass[b]
        weight = m * gravity[b]
        _limit(state, b, VELOCITY, max_speed[b])  # what impulses and scripts gave
        _limit(state, b, SPIN, max_spin[b])
        for _ in range(steps):
            _rotation(state, b, terms, rot)
            fx, fy, fz = force[b, 0], force[b, 1] - weight, force[b, 2]
            tx, ty, tz = torque[b, 0], torque[b, 1], torque[b, 2]
            v0, v1, v2 = state[b, VELOCITY], state[b, VELOCITY + 1], state[b, VELOCITY + 2]
            sub = 0.0
            if in_water:
                _water_forces(state, b, rot, shapes, half, radius, volume, gravity, samples, count, flat,
                              flat_previous, gx, gz, nx, nz, x0, z0, gh, y0, dt, density, scratch, sums)
                sub = sums[0]
                submerged[b] = sub
                fx, fy, fz = fx + sums[2], fy + sums[3], fz + sums[4]
                tx, ty, tz = tx + sums[5], ty + sums[6], tz + sums[7]
                drag = linear_drag * density * sub / m
                damp = 1.0 + h * drag
                state[b, VELOCITY] = (v0 + h * (fx / m)) / damp * decay_v[b]
                state[b, VELOCITY + 1] = (v1 + h * (fy / m + drag * sums[1])) / damp * decay_v[b]
                state[b, VELOCITY + 2] = (v2 + h * (fz / m)) / damp * decay_v[b]
            else:
                state[b, VELOCITY] = (v0 + h * (fx / m)) * decay_v[b]
                state[b, VELOCITY + 1] = (v1 + h * (fy / m)) * decay_v[b]
                state[b, VELOCITY + 2] = (v2 + h * (fz / m)) * decay_v[b]
            _limit(state, b, VELOCITY, max_speed[b])  # before the position moves with it
            # Euler's equations in the body frame: I·ω̇ = τ − ω × I·ω
            s0, s1, s2 = state[b, SPIN], state[b, SPIN + 1], state[b, SPIN + 2]
            b0 = (s0 * rot[0, 0] + s1 * rot[1, 0]) + s2 * rot[2, 0]
            b1 = (s0 * rot[0, 1] + s1 * rot[1, 1]) + s2 * rot[2, 1]
            b2 = (s0 * rot[0, 2] + s1 * rot[1, 2]) + s2 * rot[2, 2]
            i0, i1, i2 = m0 * b0, m1 * b1, m2 * b2
            a0 = (((tx * rot[0, 0] + ty * rot[1, 0]) + tz * rot[2, 0]) - (b1 * i2 - b2 * i1)) / m0
            a1 = (((tx * rot[0, 1] + ty * rot[1, 1]) + tz * rot[2, 1]) - (b2 * i0 - b0 * i2)) / m1
            a2 = (((tx * rot[0, 2] + ty * rot[1, 2]) + tz * rot[2, 2]) - (b0 * i1 - b1 * i0)) / m2
            s0 = s0 + h * ((rot[0, 0] * a0 + rot[0, 1] * a1) + rot[0, 2] * a2)
            s1 = s1 + h * ((rot[1, 0] * a0 + rot[1, 1] * a1) + rot[1, 2] * a2)
            s2 = s2 + h * ((rot[2, 0] * a0 + rot[2, 1] * a1) + rot[2, 2] * a2)
            if in_water:
                spin_drag = 1.0 + h * angular_drag * sub / volume
                s0, s1, s2 = s0 / spin_drag, s1 / spin_drag, s2 / spin_drag
            state[b, SPIN], state[b, SPIN + 1], state[b, SPIN + 2] = s0 * decay_w[b], s1 * decay_w[b], s2 * decay_w[b]
            _limit(state, b, SPIN, max_spin[b])  # before the rotation turns with it
            for k in range(3):
                state[b, POSITION + k] = state[b, POSITION + k] + h * state[b, VELOCITY + k]
            # q̇ = ½·(0, ω) ⊗ q, then normalised
            s0, s1, s2 = state[b, SPIN], state[b, SPIN + 1], state[b, SPIN + 2]
            w, x, y, z = state[b, ROTATION], state[b, ROTATION + 1], state[b, ROTATION + 2], state[b, ROTATION + 3]
            half_h = 0.5 * h
            w, x, y, z = (w + half_h * (0.0 * w - s0 * x - s1 * y - s2 * z),
                          x + half_h * (0.0 * x + s0 * w + s1 * z - s2 * y),
                          y + half_h * (0.0 * y - s0 * z + s1 * w + s2 * x),
                          z + half_h * (0.0 * z + s0 * y - s1 * x + s2 * w))
            norm = math.sqrt(0.0 + ((((0.0 + w * w) + x * x) + y * y) + z * z))
            state[b, ROTATION], state[b, ROTATION + 1] = w / norm, x / norm
            state[b, ROTATION + 2], state[b, ROTATION + 3] = y / norm, z / norm
    if contacts:
        _pool_contacts(state, shapes, half, radius, mass, restitution, friction, nx, nz, x0, z0, gh, floor, terms,
                       planes, corners)
        for b in range(n):  # contact impulses may spin a body past its limit
            _limit(state, b, VELOCITY, max_speed[b])
            _limit(state, b, SPIN, max_spin[b])


@kernel
def _contact_points(shapes, half, radius, state, b, rot, lanes, planes, corners, offsets, arms, depth):
    """Body b's contact points against each plane p, as offsets from its centre into ``arms`` (5, 8, 3): the 8 box
    corners turned with it, or the sphere's support point −r·n_p 8 times; and into ``depth`` (5, 8) how far each is
    beyond the plane, ``offsets[p]`` − n_p·(x + r). Both dot products in numpy's einsum order; for the corners that
    order depends on the rotation matrices' layout: ``lanes`` when their rows are contiguous (one body: numpy's
    fancy indexing in quat_to_matrix leaves them so only then), SIMD lanes j = 0, 2 and j = 1 from 0.0; else
    j = 0, 1, 2 in order."""
    sphere = shapes[b] == SPHERE
    for c in range(8):
        a0, a1, a2 = corners[c, 0] * half[b, 0], corners[c, 1] * half[b, 1], corners[c, 2] * half[b, 2]
        for i in range(3):  # einsum "bij,bcj->bci", added to its output's 0.0
            if lanes:
                corner = 0.0 + ((rot[i, 2] * a2 + (rot[i, 0] * a0 + 0.0)) + (0.0 * 0.0 + (rot[i, 1] * a1 + 0.0)))
            else:
                corner = 0.0 + (((0.0 + rot[i, 0] * a0) + rot[i, 1] * a1) + rot[i, 2] * a2)
            for p in range(5):
                arms[p, c, i] = (-radius[b]) * planes[p, i] if sphere else corner
    for p in range(5):
        for c in range(8):  # einsum "bpci,pi->bpc", the same loop
            e0 = (state[b, POSITION] + arms[p, c, 0]) * planes[p, 0]
            e1 = (state[b, POSITION + 1] + arms[p, c, 1]) * planes[p, 1]
            e2 = (state[b, POSITION + 2] + arms[p, c, 2]) * planes[p, 2]
            depth[p, c] = offsets[p] - (0.0 + ((e2 + (e0 + 0.0)) + (0.0 * 0.0 + (e1 + 0.0))))


@kernel
def _pool_contacts(state, shapes, half, radius, mass, restitution, friction, nx, nz, x0, z0, gh, floor, terms, planes,
                   corners):
    """bodies.pool_contacts of every body (all active), in place: nothing when no body can reach a plane or none
    touches one; else per body and plane the touching points' centroid gets a normal impulse with restitution and
    a Coulomb friction impulse (every body: one that touches nothing gets zeros added), then each body is pushed
    out by its deepest point."""
    n = len(mass)
    offsets = np.array([floor, x0, -(x0 + (nx - 1) * gh), z0, -(z0 + (nz - 1) * gh)])
    near = False
    for b in range(n):
        if shapes[b] == SPHERE:
            reach = radius[b]
        else:
            reach = math.sqrt(_sum3(half[b, 0] * half[b, 0], half[b, 1] * half[b, 1], half[b, 2] * half[b, 2]))
        for p in range(5):
            along = (state[b, POSITION] * planes[p, 0] + state[b, POSITION + 1] * planes[p, 1]) \
                + state[b, POSITION + 2] * planes[p, 2]
            if not along - reach > offsets[p]:
                near = True
    if not near:
        return
    rot = np.empty((3, 3))
    arms = np.empty((5, 8, 3))
    depth = np.empty((5, 8))
    touching = False
    for b in range(n):
        _rotation(state, b, terms, rot)
        _contact_points(shapes, half, radius, state, b, rot, n == 1, planes, corners, offsets, arms, depth)
        for p in range(5):
            for c in range(8):
                touching = touching or depth[p, c] > 0.0
    if not touching:
        return
    moments = np.empty(3)
    inv = np.empty((3, 3))
    for b in range(n):
        _rotation(state, b, terms, rot)
        _contact_points(shapes, half, radius, state, b, rot, n == 1, planes, corners, offsets, arms, depth)
        _moments(shapes, half, radius, mass, b, moments)
        for r in range(3):  # R·M⁻¹·Rᵀ
            a0, a1, a2 = rot[r, 0] / moments[0], rot[r, 1] / moments[1], rot[r, 2] / moments[2]
            for c in range(3):
                inv[r, c] = (a0 * rot[c, 0] + a1 * rot[c, 1]) + a2 * rot[c, 2]
        v0, v1, v2 = state[b, VELOCITY], state[b, VELOCITY + 1], state[b, VELOCITY + 2]
        w0, w1, w2 = state[b, SPIN], state[b, SPIN + 1], state[b, SPIN + 2]
        j0 = j1 = j2 = 0.0  # Σ over the planes of the impulses J
        l0 = l1 = l2 = 0.0  # Σ r × J
        d0 = d1 = d2 = 0.0  # Σ push-outs
        for p in range(5):
            n0, n1, n2 = planes[p, 0], planes[p, 1], planes[p, 2]
            r0 = r1 = r2 = 0.0
            count = 0
            push = 0.0
            for c in range(8):
                inside = depth[p, c] > 0.0
                if inside:
                    count += 1
                r0 = r0 + (arms[p, c, 0] if inside else 0.0)
                r1 = r1 + (arms[p, c, 1] if inside else 0.0)
                r2 = r2 + (arms[p, c, 2] if inside else 0.0)
                deepest = depth[p, c] if inside else 0.0
                push = deepest if c == 0 else maximum(push, deepest)
            share = float(max(count, 1))
            r0, r1, r2 = r0 / share, r1 / share, r2 / share  # the contact's arm
            c0, c1, c2 = v0 + (w1 * r2 - w2 * r1), v1 + (w2 * r0 - w0 * r2), v2 + (w0 * r1 - w1 * r0)
            vn = _sum3(c0 * n0, c1 * n1, c2 * n2)
            e0, e1, e2 = r1 * n2 - r2 * n1, r2 * n0 - r0 * n2, r0 * n1 - r1 * n0  # r × n, then I⁻¹·(r × n)
            e0, e1, e2 = ((inv[0, 0] * e0 + inv[0, 1] * e1) + inv[0, 2] * e2,
                          (inv[1, 0] * e0 + inv[1, 1] * e1) + inv[1, 2] * e2,
                          (inv[2, 0] * e0 + inv[2, 1] * e1) + inv[2, 2] * e2)
            k = 1.0 / mass[b] + _sum3((e1 * r2 - e2 * r1) * n0, (e2 * r0 - e0 * r2) * n1, (e0 * r1 - e1 * r0) * n2)
            jn = -(1.0 + restitution[b]) * vn / k if count > 0 and vn < 0.0 else 0.0
            t0, t1, t2 = c0 - vn * n0, c1 - vn * n1, c2 - vn * n2
            speed = math.sqrt(_sum3(t0 * t0, t1 * t1, t2 * t2))
            jt = minimum(friction[b] * jn, speed / k)
            unit = speed if speed > 0.0 else 1.0
            i0, i1, i2 = jn * n0 - jt * (t0 / unit), jn * n1 - jt * (t1 / unit), jn * n2 - jt * (t2 / unit)
            j0, j1, j2 = j0 + i0, j1 + i1, j2 + i2
            l0, l1, l2 = l0 + (r1 * i2 - r2 * i1), l1 + (r2 * i0 - r0 * i2), l2 + (r0 * i1 - r1 * i0)
            d0, d1, d2 = d0 + push * n0, d1 + push * n1, d2 + push * n2
        m = mass[b]
        state[b, VELOCITY], state[b, VELOCITY + 1], state[b, VELOCITY + 2] = v0 + j0 / m, v1 + j1 / m, v2 + j2 / m
        state[b, SPIN] = w0 + ((inv[0, 0] * l0 + inv[0, 1] * l1) + inv[0, 2] * l2)
        state[b, SPIN + 1] = w1 + ((inv[1, 0] * l0 + inv[1, 1] * l1) + inv[1, 2] * l2)
        state[b, SPIN + 2] = w2 + ((inv[2, 0] * l0 + inv[2, 1] * l1) + inv[2, 2] * l2)
        state[b, POSITION] = state[b, POSITION] + (0.0 + d0)
        state[b, POSITION + 1] = state[b, POSITION + 1] + (0.0 + d1)
        state[b, POSITION + 2] = state[b, POSITION + 2] + (0.0 + d2)
