"""Comparing apertures from frame to frame.

:func:`aperture_iou` compares two apertures and :class:`ApertureTracker` decides from it
whether a fitter built for an earlier aperture can be reused.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import is_real
from .region import Aperture


@dataclass(frozen=True)
class ApertureChange:
    """Verdict of :meth:`ApertureTracker.update`.

    Attributes
    ----------
    changed : bool
        True when a fitter built for the reference aperture must not be reused.
    iou : float
        Intersection over union with the reference aperture (0.0 when there is none or the
        shapes differ).
    reason : str
        Human-readable explanation.
    """

    changed: bool
    iou: float
    reason: str


def aperture_iou(a: Aperture | ArrayLike, b: Aperture | ArrayLike) -> float:
    """Intersection over union (Jaccard index) of two apertures or masks.

    Parameters
    ----------
    a, b : Aperture or array_like, shape (rows, cols)
        Apertures, or masks (bool or finite real; non-zero = valid) of the same shape.

    Returns
    -------
    float
        ``|A & B| / |A | B|`` in [0, 1]: 1 for identical masks, 0 for disjoint ones.

    Raises
    ------
    ValueError
        If a mask is not a 2-D bool or finite real array, the shapes differ, or both masks are
        empty (IoU undefined).

    References
    ----------
    .. [1] P. Jaccard, "The distribution of the flora in the alpine zone", New Phytologist
       11(2), 37-50 (1912).
    """
    mask_a = _as_mask("a", a)
    mask_b = _as_mask("b", b)
    if mask_a.shape != mask_b.shape:
        raise ValueError(
            f"a has shape {mask_a.shape} and b has shape {mask_b.shape}; expected equal shapes"
        )
    union = int(np.count_nonzero(mask_a | mask_b))
    if union == 0:
        raise ValueError("a and b are both empty; expected at least one valid pixel")
    return int(np.count_nonzero(mask_a & mask_b)) / union


def compare_apertures(reference: Aperture, aperture: Aperture, iou_threshold: float) -> ApertureChange:
    """Is ``aperture`` the same aperture as ``reference`` for a fitter built on the latter?

    Parameters
    ----------
    reference, aperture : Aperture
    iou_threshold : float
        Smallest intersection over union that counts as the same aperture, in (0, 1].

    Returns
    -------
    ApertureChange
        ``changed`` when the mask shapes differ, the topology or the number of components
        differs, or the IoU is below ``iou_threshold``; ``reason`` says which.
    """
    if reference.shape != aperture.shape:
        return ApertureChange(True, 0.0, f"mask shape changed from {reference.shape} to {aperture.shape}")
    iou = aperture_iou(reference, aperture)
    if (reference.topology, reference.components) != (aperture.topology, aperture.components):
        return ApertureChange(
            True, iou, f"topology changed from {reference.describe()!r} to {aperture.describe()!r}"
        )
    if iou < iou_threshold:
        return ApertureChange(True, iou, f"IoU {iou:.4f} below threshold {iou_threshold:g}")
    return ApertureChange(False, iou, f"IoU {iou:.4f} >= threshold {iou_threshold:g}")


class ApertureTracker:
    """Decide, frame after frame, whether a fitter built for an earlier aperture is reusable.

    The tracker holds a reference aperture: the one the current fitter was built for. Each
    :meth:`update` compares the new aperture with it; when the change is too large the new
    aperture becomes the reference (build a new fitter). An unchanged verdict leaves the
    reference alone, so a slow drift accumulates until it crosses the threshold. Not
    thread-safe.

    Parameters
    ----------
    iou_threshold : float, optional
        Smallest intersection over union with the reference for which the aperture counts as
        unchanged; must be in (0, 1]. Default 0.98.

    Raises
    ------
    ValueError
        If ``iou_threshold`` is not a real number in (0, 1].
    """

    def __init__(self, iou_threshold: float = 0.98) -> None:
        if (
            not is_real(iou_threshold)
            or not 0.0 < float(iou_threshold) <= 1.0
        ):
            raise ValueError(f"iou_threshold is {iou_threshold!r}; expected a number in (0, 1]")
        self._iou_threshold = float(iou_threshold)
        self._reference: Aperture | None = None

    @property
    def iou_threshold(self) -> float:
        """Smallest IoU with the reference that counts as unchanged."""
        return self._iou_threshold

    @property
    def reference(self) -> Aperture | None:
        """The aperture the current fitter was built for (None before the first update)."""
        return self._reference

    def reset(self) -> None:
        """Forget the reference; the next :meth:`update` reports a change."""
        self._reference = None

    def update(self, aperture: Aperture) -> ApertureChange:
        """Compare a new aperture with the reference.

        Parameters
        ----------
        aperture : Aperture
            Aperture of the current frame.

        Returns
        -------
        ApertureChange
            ``changed`` is True on the first call (or after :meth:`reset`), when the mask
            shape, the topology or the number of components differs, or when the IoU with the
            reference is below ``iou_threshold``; the new aperture then becomes the
            reference.

        Raises
        ------
        ValueError
            If ``aperture`` is not an :class:`Aperture`.
        """
        if not isinstance(aperture, Aperture):
            raise ValueError(f"aperture is {type(aperture).__name__}; expected an Aperture")
        reference = self._reference
        if reference is None:
            change = ApertureChange(True, 0.0, "no reference aperture yet")
        else:
            change = compare_apertures(reference, aperture, self._iou_threshold)
        if change.changed:
            self._reference = aperture
        return change


def _as_mask(name: str, value: Aperture | ArrayLike) -> NDArray[np.bool_]:
    """The mask of an Aperture, or a checked 2-D array as booleans (non-zero = valid)."""
    if isinstance(value, Aperture):
        return value.mask
    expected = "expected an Aperture or a 2-D array of booleans or finite real numbers"
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} could not be converted to an array ({exc}); {expected}") from exc
    if array.ndim != 2 or array.dtype.kind not in "biuf":
        raise ValueError(f"{name} has shape {array.shape}, dtype {array.dtype}; {expected}")
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise ValueError(f"{name} has NaN or infinite entries; {expected}")
    return array != 0
