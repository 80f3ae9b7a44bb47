"""Motive's Y-up axes become perchd's Z-up world, checked against rotation matrices."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from perchd.core.errors import UriError
from perchd.mocap.frames import UpAxis, from_world, to_world

Y_UP_TO_Z_UP = Rotation.from_euler("x", 90, degrees=True)


def test_motive_up_becomes_world_up_and_handedness_is_kept():
    level = (0.0, 0.0, 0.0, 1.0)
    x, y, z = (to_world(axis, level, UpAxis.Y)[0] for axis in np.eye(3))
    assert y == (0.0, 0.0, 1.0)  # Motive's up is the world's up
    assert x == (1.0, 0.0, 0.0)
    assert np.linalg.det(np.column_stack([x, y, z])) == pytest.approx(1.0)  # still right-handed


@pytest.mark.parametrize("seed", range(5))
def test_a_rotated_body_has_the_same_attitude_seen_from_either_frame(seed):
    rng = np.random.default_rng(seed)
    in_motive = Rotation.random(random_state=seed)
    p_motive = tuple(rng.uniform(-3, 3, 3))
    p, q = to_world(p_motive, tuple(in_motive.as_quat()), UpAxis.Y)
    assert np.allclose(p, Y_UP_TO_Z_UP.apply(p_motive))
    expected = Y_UP_TO_Z_UP * in_motive * Y_UP_TO_Z_UP.inv()
    assert np.allclose(Rotation.from_quat(q).as_matrix(), expected.as_matrix())


def test_from_world_inverts_to_world_and_z_up_is_untouched():
    p, q = (1.0, 2.0, 3.0), (0.1, 0.2, 0.3, 0.9)
    assert to_world(*from_world(p, q, UpAxis.Y), UpAxis.Y) == (p, q)
    assert to_world(p, q, UpAxis.Z) == (p, q)


def test_an_unknown_up_axis_is_a_uri_error():
    with pytest.raises(UriError, match="up='x' must be y"):
        UpAxis.parse("x", "natnet://h?up=x")
