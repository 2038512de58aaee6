"""A small aircraft-shaped mesh and the rotation that puts it in the ENU scene.

The mesh is drawn in a forward-left-up body frame (x nose, y left wing, z up). Mapping aviation
angles onto that frame: heading ``psi`` is clockwise from north while yaw about +z in ENU is
counter-clockwise from east, so yaw = pi/2 - psi; nose-up pitch is a negative rotation about
the left-wing axis; right-wing-down bank is a positive rotation about the nose.
"""

from __future__ import annotations

import numpy as np

# Real small UAVs are ~2-3 m across; in a 2 km scene they would be sub-pixel.
DEFAULT_SPAN_M = 70.0

# Unit-span outline: a diamond fuselage, a swept wing, a tailplane and a fin.
_VERTICES = np.array(
    [
        # fuselage: nose, tail, ring at the wing root (top, left, bottom, right)
        [0.45, 0.0, 0.0],
        [-0.45, 0.0, 0.0],
        [0.12, 0.0, 0.05],
        [0.12, 0.05, 0.0],
        [0.12, 0.0, -0.05],
        [0.12, -0.05, 0.0],
        # wing: root leading edge, left tip, root trailing edge, right tip
        [0.18, 0.0, 0.0],
        [-0.02, 0.5, 0.0],
        [-0.08, 0.0, 0.0],
        [-0.02, -0.5, 0.0],
        # tailplane: root leading edge, left tip, root trailing edge, right tip
        [-0.3, 0.0, 0.0],
        [-0.45, 0.18, 0.0],
        [-0.45, 0.0, 0.0],
        [-0.45, -0.18, 0.0],
        # fin: root leading edge, tip
        [-0.28, 0.0, 0.0],
        [-0.45, 0.0, 0.17],
    ]
)
_TRIANGLES = np.array(
    [
        [0, 2, 3],
        [0, 3, 4],
        [0, 4, 5],
        [0, 5, 2],
        [1, 3, 2],
        [1, 4, 3],
        [1, 5, 4],
        [1, 2, 5],
        [6, 7, 8],
        [6, 8, 9],
        [10, 11, 12],
        [10, 12, 13],
        [14, 12, 15],
    ],
    dtype=np.uint32,
)


def aircraft_mesh(span_m: float = DEFAULT_SPAN_M) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (3F, 3) in the body frame scaled to ``span_m``, their normals, triangles (F, 3)).

    Every triangle gets its own three vertices so that each face carries its own normal: the
    viewer then shades the faces differently and the shape reads as a solid.
    """
    corners = _VERTICES[_TRIANGLES] * span_m  # (F, 3 corners, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    faces = np.arange(corners.shape[0] * 3, dtype=np.uint32).reshape(-1, 3)
    return corners.reshape(-1, 3), np.repeat(normals, 3, axis=0), faces


def attitude_quaternions(att: np.ndarray) -> np.ndarray:
    """Quaternions (N, 4) as x, y, z, w from rows of (phi, theta, psi) in radians.

    Intrinsic z-y-x rotation with yaw = pi/2 - psi, pitch = -theta, roll = phi (see module doc).
    """
    att = np.atleast_2d(np.asarray(att, dtype=np.float64))
    half_roll = 0.5 * att[:, 0]
    half_pitch = -0.5 * att[:, 1]
    half_yaw = 0.5 * (0.5 * np.pi - att[:, 2])
    cr, sr = np.cos(half_roll), np.sin(half_roll)
    cp, sp = np.cos(half_pitch), np.sin(half_pitch)
    cy, sy = np.cos(half_yaw), np.sin(half_yaw)
    return np.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=1,
    )


def rotate(quaternion: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Rotate ``vector`` (3,) by one x, y, z, w quaternion; what the viewer does to the mesh."""
    q = np.asarray(quaternion, dtype=np.float64)
    u, w = q[:3], q[3]
    v = np.asarray(vector, dtype=np.float64)
    return v + 2.0 * w * np.cross(u, v) + 2.0 * np.cross(u, np.cross(u, v))
