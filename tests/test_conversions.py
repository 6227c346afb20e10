"""Hand-written conversions kept beside the library that would do the same job (the reason is
in each one's docstring) agree with that library."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from pslog.log import _schemas as S


def test_quaternions_are_scipys():
    rotations = Rotation.random(2000, random_state=7)
    # and the awkward ones: identity, half turns about each axis, a turn near pi
    special = Rotation.from_rotvec(np.array([[0, 0, 0], [np.pi, 0, 0], [0, np.pi, 0],
                                             [0, 0, np.pi], [0, 0, np.pi - 1e-9],
                                             [1e-12, 0, 0]]))
    for rot in [*rotations, *special]:
        matrix = rot.as_matrix()
        ours = S.quaternion_xyzw(matrix)
        assert ours[3] >= 0
        theirs = rot.as_quat(canonical=True)
        if abs(theirs[3]) < 1e-12:  # w = 0: q and -q are both canonical up to a sign
            theirs = theirs * np.sign(np.dot(theirs, ours))
        assert_allclose(ours, theirs, atol=1e-15)
        assert_allclose(S.rotation_from_quaternion(ours),
                        Rotation.from_quat(ours).as_matrix(), atol=1e-15)
