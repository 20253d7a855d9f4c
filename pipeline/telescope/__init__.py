"""The optical design model of an off-axis three-mirror anastigmat (TMA), ray traced with batoid.

The model both sides of an alignment bench use: the controller (``wavestack.align``) computes its
sensitivity matrix from it, and the simulated bench renders its truth with it.

- :class:`TmaDesign` describes the telescope (from ``[tma]`` in a config file); :class:`TmaModel`
  is the telescope as built (the design, optionally with seeded rigid-body errors of the other
  mirrors, :class:`AsBuiltErrors`, and a mount error of the aligned one), whose
  :meth:`TmaModel.wavefront` gives the map the interferometer sees at a field point with the
  aligned mirror at a :class:`HexapodPose`;
- the hexapod's pose and pivot convention (PI's X Y Z U V W, rotations about the moving axes U
  then V then W, about the pivot: :func:`pose_rotation`, :func:`transform_point`);
- the sensitivity of the terms at every field point to the degrees of freedom :data:`DOFS`
  (:func:`build_sensitivity`: central differences of the model, columns normalised);
- the interferometer reference's tilt an operator sets at each field point (:func:`centring_tilt`).

This topic stands apart from the face ``wavestack.pipeline`` (which does not re-export it): it
needs batoid, which only the alignment loop and its simulator load.
"""

from __future__ import annotations

from .design import PupilShape, TmaDesign, TmaMirror
from .model import TmaModel
from .optic import AsBuiltErrors, MirrorError, build_optic, draw_as_built
from .pose import HexapodPose, pose_rotation, rotation_x, rotation_y, rotation_z, transform_point
from .reference import TILT_RESOLUTION, ReferenceTilt, centring_tilt
from .sensitivity import DOFS, Sensitivity, TermFit, WavefrontModel, build_sensitivity, model_terms

__all__ = ["AsBuiltErrors", "DOFS", "HexapodPose", "MirrorError", "PupilShape", "ReferenceTilt", "Sensitivity",
           "TILT_RESOLUTION", "TermFit", "TmaDesign", "TmaMirror", "TmaModel", "WavefrontModel", "build_optic",
           "build_sensitivity", "centring_tilt", "draw_as_built", "model_terms", "pose_rotation", "rotation_x",
           "rotation_y", "rotation_z", "transform_point"]
