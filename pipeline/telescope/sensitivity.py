"""The sensitivity matrix: how the Zernike terms at every field point move per degree of freedom.

Built as Rubin Observatory's active optics builds its matrix (lsst-ts/ts_ofc; background in
/work/shared/reference/closed-loops.md): finite differences of a ray-traced design model, one
column per degree of freedom, the rows the terms of every field point stacked. Two choices of
ours, both for numerical soundness:

- *central* differences about the current estimate (not one-sided about the design): the
  terms are quadratic in the pose near alignment (a despace's defocus is linear, but coma from a
  decentre combined with a tilt is not), and re-linearising at the current estimate each
  iteration is what Lee et al. (Opt. Express 15, 3127, 2007) found the non-linear coupling needs;
- each column scaled by the degree of freedom's *range* (``scales``, mm or deg): the solver then
  sees dimensionless unknowns of order one, so one singular-value threshold treats a 0.1 mm
  decentre and a 0.01 deg tilt alike (Rubin normalises its columns by DOF weights the same way).

W (rotation about the axis) is left out: the sensitivity of the terms to W is zero to the
model's precision for a mirror symmetric about its own axis (the mount model's W is
unobservable, tests/pipeline/telescope), so it can only add noise to the solve; the loop never moves W.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .pose import HexapodPose

__all__ = ["DOFS", "Sensitivity", "TermFit", "WavefrontModel", "build_sensitivity", "model_terms"]

#: The degrees of freedom the loop estimates and moves (PI's axis names); W is unobservable.
DOFS: tuple[str, ...] = ("X", "Y", "Z", "U", "V")

FloatArray = NDArray[np.float64]
WavefrontModel = Callable[[tuple[float, float], HexapodPose], NDArray[np.floating]]


class TermFit(Protocol):
    """What the matrix is fitted with: the terms of a map (H, W) in waves, shape (T,).

    The alignment loop passes its measurement's fitter, so the model and the measurement are
    fitted in one basis on one aperture.
    """

    def terms(self, waves: NDArray[np.floating]) -> FloatArray: ...


@dataclass(frozen=True, eq=False)
class Sensitivity:
    """The linear model ``terms(s) ~ nominal + matrix @ ((s - at) / scales)``.

    Attributes
    ----------
    matrix : ndarray (F * T, D)
        Waves of each term per unit of normalised degree of freedom (``scales`` units), rows field
        point-major (field 0's T terms first).
    nominal : ndarray (F * T,)
        The model's terms at ``at``, waves.
    at : ndarray (D,)
        The state linearised about: X Y Z mm, U V deg.
    scales : ndarray (D,)
        The normalisation of each column, mm or deg.
    """

    matrix: FloatArray
    nominal: FloatArray
    at: FloatArray
    scales: FloatArray


def _pose(state: FloatArray) -> HexapodPose:
    x, y, z, u, v = (float(value) for value in state)
    return HexapodPose(x, y, z, u, v, 0.0)


def model_terms(model: WavefrontModel, fields: Sequence[tuple[float, float]], fitter: TermFit,
                state: NDArray[np.floating]) -> FloatArray:
    """The model's terms at every field point for ``state`` (X Y Z mm, U V deg), shape (F * T,)."""
    pose = _pose(np.asarray(state, dtype=np.float64))
    return np.concatenate([fitter.terms(model(tuple(field), pose)) for field in fields])  # type: ignore[arg-type]


def build_sensitivity(model: WavefrontModel, fields: Sequence[tuple[float, float]], fitter: TermFit, *,
                      at: NDArray[np.floating], steps: NDArray[np.floating],
                      scales: NDArray[np.floating]) -> Sensitivity:
    """Central-difference sensitivity matrix about ``at`` (module notes).

    Parameters
    ----------
    model : callable
        ``model(field_deg, pose) -> waves (H, W)``: the *design* telescope (no as-built errors).
    fields : sequence of (float, float)
        Field points, deg.
    fitter : TermFit
        The measurement's fitter (same method on the same aperture: one basis).
    at, steps, scales : array (5,)
        State to linearise about, finite-difference half steps, column normalisation
        (X Y Z mm, U V deg); steps and scales > 0.

    Returns
    -------
    Sensitivity

    Examples
    --------
    A model whose first three terms are the pose's X, Y, Z (and a fitter that reads them):

    >>> class FirstRow:
    ...     def terms(self, waves):
    ...         return np.asarray(waves[0, :5], dtype=np.float64)
    >>> model = lambda field, pose: np.tile([pose.x, pose.y, pose.z, 0.0, 0.0], (2, 1))
    >>> s = build_sensitivity(model, [(0.0, 0.0)], FirstRow(), at=np.zeros(5), steps=np.full(5, 1e-3),
    ...                       scales=np.full(5, 0.1))
    >>> bool(np.allclose(s.matrix[:3, :3], 0.1 * np.eye(3)))
    True
    """
    at = np.asarray(at, dtype=np.float64)
    steps = np.asarray(steps, dtype=np.float64)
    scales = np.asarray(scales, dtype=np.float64)
    for name, values in (("at", at), ("steps", steps), ("scales", scales)):
        if values.shape != (len(DOFS),) or not np.all(np.isfinite(values)):
            raise ValueError(f"{name}: expected {len(DOFS)} finite values ({' '.join(DOFS)}), got {values}")
    if not (np.all(steps > 0) and np.all(scales > 0)):
        raise ValueError(f"steps and scales: expected > 0, got {steps} and {scales}")
    nominal = model_terms(model, fields, fitter, at)
    columns = []
    for k in range(len(DOFS)):
        delta = np.zeros(len(DOFS))
        delta[k] = steps[k]
        plus = model_terms(model, fields, fitter, at + delta)
        minus = model_terms(model, fields, fitter, at - delta)
        columns.append((plus - minus) / (2 * steps[k]) * scales[k])
    return Sensitivity(np.column_stack(columns), nominal, at.copy(), scales.copy())
