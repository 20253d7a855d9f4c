"""A simulated off-axis three-mirror anastigmat (TMA), ray traced with batoid.

:class:`TmaDesign` describes the telescope (from ``[tma]`` in a config file,
:mod:`wavestack.config.tma`); :class:`TmaModel` is the as-built telescope with seeded errors, whose
:meth:`TmaModel.wavefront` gives the map the interferometer sees at a field point with the aligned
mirror at a :class:`HexapodPose` (PI's X Y Z U V W about the pivot, :func:`pose_rotation`).
"""

from __future__ import annotations

from .design import PupilShape, TmaDesign, TmaMirror
from .model import TmaModel
from .optic import AsBuiltErrors, MirrorError, build_optic, draw_as_built
from .pose import HexapodPose, pose_rotation, rotation_x, rotation_y, rotation_z, transform_point

__all__ = ["AsBuiltErrors", "HexapodPose", "MirrorError", "PupilShape", "TmaDesign", "TmaMirror", "TmaModel",
           "build_optic", "draw_as_built", "pose_rotation", "rotation_x", "rotation_y", "rotation_z",
           "transform_point"]
