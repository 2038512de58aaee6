"""The model's attitude in the ENU scene: nose along the heading, right wing down in a bank."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.recording.aircraft_model import aircraft_mesh, attitude_quaternions, rotate

NOSE, LEFT_WING, UP = np.eye(3)


def pose(phi_deg: float = 0.0, theta_deg: float = 0.0, psi_deg: float = 0.0) -> np.ndarray:
    return attitude_quaternions(np.radians([[phi_deg, theta_deg, psi_deg]]))[0]


@pytest.mark.parametrize(
    ("psi_deg", "east", "north"),
    [(0, 0, 1), (90, 1, 0), (180, 0, -1), (270, -1, 0), (45, math.sqrt(0.5), math.sqrt(0.5))],
)
def test_nose_points_along_heading_clockwise_from_north(psi_deg, east, north):
    np.testing.assert_allclose(rotate(pose(psi_deg=psi_deg), NOSE), [east, north, 0], atol=1e-12)


def test_positive_bank_puts_the_right_wing_down():
    q = pose(phi_deg=30, psi_deg=90)  # heading east: the right wing points south
    right_wing = rotate(q, -LEFT_WING)
    assert right_wing[2] == pytest.approx(-0.5)
    assert right_wing[1] == pytest.approx(-math.cos(math.radians(30)))
    np.testing.assert_allclose(rotate(q, NOSE), [1, 0, 0], atol=1e-12)


def test_positive_pitch_raises_the_nose_without_changing_its_bearing():
    nose = rotate(pose(theta_deg=10, psi_deg=0), NOSE)
    assert nose[2] == pytest.approx(math.sin(math.radians(10)))
    assert nose[0] == pytest.approx(0.0, abs=1e-12) and nose[1] > 0


def test_quaternions_are_unit_and_batched():
    att = np.random.default_rng(0).uniform(-3, 3, size=(100, 3))
    q = attitude_quaternions(att)
    assert q.shape == (100, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0)


def test_mesh_spans_the_requested_width_with_unit_normals():
    vertices, normals, triangles = aircraft_mesh(span_m=50.0)
    assert np.ptp(vertices[:, 1]) == pytest.approx(50.0)  # wing tip to wing tip
    assert np.ptp(vertices[:, 0]) < 50.0  # shorter than it is wide, like a small UAV
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert triangles.max() < len(vertices)
