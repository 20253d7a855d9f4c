"""The hexapod pose of the aligned mirror: (X, Y, Z) mm and (U, V, W) deg about a pivot point.

PI's hexapod manuals (H-845 MS222E, H-820 MS207E, H-850 MS202E, "Product Description ->
Rotation"; read through manualshive.com, e.g. https://manualshive.com/ru/manual/pi/h-845/1554367?page=29)
say: "Rotations take place around the rotational axes U, V and W. The rotational axes meet at
the center of rotation (also referred to as 'pivot point'). The rotational axes and therefore
also the center of rotation always move together with the platform of the hexapod ... A given
rotation in space is calculated from the individual rotations in the order U -> V -> W."
Translations are "described in the spatially-fixed coordinate system".

Rotations in the order U, V, W about axes that move with the platform are intrinsic rotations,
so the platform's attitude is ``R = Rx(U) @ Ry(V) @ Rz(W)``, which is the same matrix as
rotating about the *fixed* axes in the order W, V, U. This differs from the working contract's
``Rz(W) Ry(V) Rx(U)`` (fixed axes in the order U, V, W); the manual's text is what we follow.
For the tilts of an alignment (hundredths of a degree) the two differ by ~1e-7 rad. (The manuals'
figure "Example: Consecutive rotations" that illustrates the moving axes was not readable through
the text copies; the sentence above is what this rule rests on.)

A point ``p`` of the platform goes to ``p' = pivot + t + R (p - pivot)``: the pivot travels with
the translation ``t = (X, Y, Z)`` and the rotation leaves it fixed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["HexapodPose", "pose_rotation", "rotation_x", "rotation_y", "rotation_z", "transform_point"]

FloatArray = NDArray[np.float64]


def rotation_x(angle_deg: float) -> FloatArray:
    """Right-handed rotation by ``angle_deg`` about +x, shape (3, 3)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_deg: float) -> FloatArray:
    """Right-handed rotation by ``angle_deg`` about +y, shape (3, 3)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_deg: float) -> FloatArray:
    """Right-handed rotation by ``angle_deg`` about +z, shape (3, 3)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def pose_rotation(u_deg: float, v_deg: float, w_deg: float) -> FloatArray:
    """The platform attitude for PI's U, V, W: ``Rx(U) @ Ry(V) @ Rz(W)`` (see the module notes).

    Examples
    --------
    >>> bool(np.allclose(pose_rotation(0.0, 90.0, 0.0) @ [0, 0, 1], [1, 0, 0]))
    True
    """
    return rotation_x(u_deg) @ rotation_y(v_deg) @ rotation_z(w_deg)


@dataclass(frozen=True)
class HexapodPose:
    """A hexapod pose: translations mm, rotations deg (PI's X Y Z U V W).

    Examples
    --------
    >>> HexapodPose(z=0.1).as_tuple()
    (0.0, 0.0, 0.1, 0.0, 0.0, 0.0)
    """

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    u: float = 0.0
    v: float = 0.0
    w: float = 0.0

    def __post_init__(self) -> None:
        for name, value in zip("xyzuvw", self.as_tuple()):
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
                raise ValueError(f"pose {name.upper()}: expected a finite number, got {value!r}")
            if name in "uvw" and abs(value) > 30.0:
                raise ValueError(f"pose {name.upper()}: expected |angle| <= 30 deg, got {value!r}")

    @classmethod
    def from_sequence(cls, values: ArrayLike) -> HexapodPose:
        """A pose from ``(X, Y, Z, U, V, W)``; ValueError if there are not six values."""
        seq = [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]
        if len(seq) != 6:
            raise ValueError(f"pose: expected 6 values (X, Y, Z, U, V, W), got {len(seq)}")
        return cls(*seq)

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        """``(X, Y, Z, U, V, W)``."""
        return (self.x, self.y, self.z, self.u, self.v, self.w)

    def rotation(self) -> FloatArray:
        """The attitude matrix :func:`pose_rotation` ``(U, V, W)``."""
        return pose_rotation(self.u, self.v, self.w)


def transform_point(point: ArrayLike, pose: HexapodPose, pivot: ArrayLike) -> FloatArray:
    """Where a platform point goes: ``pivot + t + R (point - pivot)``, mm, shape (3,) or (N, 3)."""
    p = np.asarray(point, dtype=np.float64)
    c = np.asarray(pivot, dtype=np.float64)
    t = np.array([pose.x, pose.y, pose.z])
    return c + t + (p - c) @ pose.rotation().T
