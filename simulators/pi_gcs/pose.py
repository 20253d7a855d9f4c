"""The platform's pose: a snapshot of the axis positions, and the rigid motion a hexapod pose means.

PI's hexapod manuals define the pose (H-820 manual MS207E v2.3.0, section 3.7.4 "Motion"; the same
text in the H-845 MS222E and H-850 MS202E manuals): translations X, Y, Z are along the spatially
fixed axes; rotations U, V, W are about axes that meet at the pivot point ("center of
rotation"), and "the rotational axes and therefore also the center of rotation always move
together with the platform"; "a given rotation in space is calculated from the individual
rotations in the order U -> V -> W". Rotations about axes that move with the platform, U first,
compose as R = Rx(U) Ry(V) Rz(W) (intrinsic rotations; the driver and the TMA model read the
manual the same way, ``wavestack.pipeline.telescope.pose``).
A point p of the platform (coordinates at the zero pose) is therefore carried to

    p' = R (p - c) + c + T,    T = (X, Y, Z),  c = pivot (R, S, T of ``SPI``)

so the pivot point itself moves only by T: that is what "keeps the pivot" means.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["SimPose", "platform_transform", "rotation_matrix"]


@dataclass(frozen=True)
class SimPose:
    """Positions of every axis at one instant (mm for X Y Z, deg for U V W).

    Examples
    --------
    >>> pose = SimPose(("X", "Y"), (1.0, -2.0))
    >>> pose["Y"], pose.as_dict()
    (-2.0, {'X': 1.0, 'Y': -2.0})
    """

    axes: tuple[str, ...]
    values: tuple[float, ...]

    def __getitem__(self, axis: str) -> float:
        try:
            return self.values[self.axes.index(axis)]
        except ValueError:
            raise KeyError(f"no axis {axis!r}; the axes are {list(self.axes)}") from None

    def get(self, axis: str, default: float = 0.0) -> float:
        """Position of ``axis``, or ``default`` for an axis the controller does not have."""
        return self[axis] if axis in self.axes else default

    def as_dict(self) -> dict[str, float]:
        """``{axis: position}`` in controller order."""
        return dict(zip(self.axes, self.values))


def rotation_matrix(u_deg: float, v_deg: float, w_deg: float) -> NDArray[np.float64]:
    """R = Rx(U) Ry(V) Rz(W): U about X first, then V about the platform's Y, then W about its Z.

    Returns
    -------
    (3, 3) rotation matrix.

    Examples
    --------
    >>> r = rotation_matrix(0.0, 0.0, 90.0)
    >>> np.allclose(r @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    True
    """
    u, v, w = (math.radians(a) for a in (u_deg, v_deg, w_deg))
    rx = np.array([[1, 0, 0], [0, math.cos(u), -math.sin(u)], [0, math.sin(u), math.cos(u)]])
    ry = np.array([[math.cos(v), 0, math.sin(v)], [0, 1, 0], [-math.sin(v), 0, math.cos(v)]])
    rz = np.array([[math.cos(w), -math.sin(w), 0], [math.sin(w), math.cos(w), 0], [0, 0, 1]])
    return rx @ ry @ rz


def platform_transform(pose: SimPose | Mapping[str, float],
                       pivot: tuple[float, float, float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The rigid motion of the platform: ``p' = R @ p + t`` for platform points ``p`` (mm).

    Parameters
    ----------
    pose
        Positions of X Y Z (mm) and U V W (deg); missing axes count as 0.
    pivot
        Pivot point (R, S, T), mm, in the platform's zero-pose coordinates.

    Returns
    -------
    R : (3, 3) rotation, t : (3,) translation, mm, with t = T + c - R c (see the module docstring).

    Examples
    --------
    >>> r, t = platform_transform({"W": 90.0}, (10.0, 0.0, 0.0))
    >>> np.allclose(r @ [10.0, 0.0, 0.0] + t, [10.0, 0.0, 0.0])  # the pivot stays put
    True
    """
    get = pose.get if isinstance(pose, SimPose) else (lambda a: float(pose.get(a, 0.0)))
    rotation = rotation_matrix(get("U"), get("V"), get("W"))
    centre = np.asarray(pivot, dtype=float)
    translation = np.array([get("X"), get("Y"), get("Z")], dtype=float)
    return rotation, translation + centre - rotation @ centre
