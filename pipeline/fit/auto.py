"""Choosing the fit method for an aperture: the ``auto`` method, and advice that works when a
method fails.

``auto`` fits Zernike circle polynomials where they are well conditioned on the aperture and the
CSF-QCM mapped basis where they are not (long thin strips, narrow ellipses, half disks), and says
which it chose and why (``FitterDiagnostics.method_reason``).

"Well conditioned" is measured by the noise gain of the circle basis on the samples,
``g = sqrt(trace(G^-1) / M)`` (:func:`~wavestack.pipeline.fit.conditioning.noise_gain`): the factor
by which white pixel noise in the coefficients exceeds that of a basis orthonormal on the samples.
The threshold ``AUTO_MAX_NOISE_GAIN = 100`` is the level at which ``wavestack fit`` already warns
that single coefficients mean little (0.01 wave of pixel noise becomes ~1 wave of coefficient
scatter at N/M ~ 1e4); below it the circle coefficients keep their usual meaning (a full disk
gives 1.0, an annulus of obscuration 0.5 about 2, an inscribed square about 14), above it
crosstalk dominates (a 2:1 ellipse gives about 400, a 259 x 33 strip about 5e6, whose
kappa(G) ~ 4e15 sits at the float64 limit). The gain is preferred to kappa(G) because it is the
figure a user feels (coefficient scatter), and kappa(G) of a well-sampled disk is ~1 anyway.
The paper motivates the mapped basis by exactly this loss of orthogonality on non-circular
apertures (seed paper, section 1 and section 3.2.2, Table 1).
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Callable

from ..aperture import Aperture, Topology, UnsupportedAperture
from .conditioning import WELL_CONDITIONED_NOISE_GAIN
from .fitter import Fitter
from .normal_equations import IllConditionedBasis
from .orthonormal import distinct_figures

logger = logging.getLogger(__name__)

AUTO = "auto"
AUTO_MAX_NOISE_GAIN = WELL_CONDITIONED_NOISE_GAIN  # 100; see the module docstring

BuildOne = Callable[..., Fitter]  # build(method, **overrides) -> Fitter


def _with_reason(fitter: Fitter, reason: str) -> Fitter:
    fitter.diagnostics = dataclasses.replace(fitter.diagnostics, method_reason=reason)
    logger.info("auto fit method: %s (%s)", fitter.basis.method, reason)
    return fitter


def build_auto(build: BuildOne, aperture: Aperture) -> Fitter:
    """Build the circle fitter if its noise gain is at most ``AUTO_MAX_NOISE_GAIN``, else the
    ``csf-qcm`` fitter (or ``qr`` for an aperture no map can handle).

    Parameters
    ----------
    build : callable
        ``build(method)`` returns the fitter of one concrete method on the aperture.
    aperture : Aperture

    Returns
    -------
    Fitter
        Its ``diagnostics.method`` is the method chosen, ``diagnostics.method_reason`` says why.

    Raises
    ------
    IllConditionedBasis
        If the chosen mapped or ``qr`` method cannot fit the modes either (too many modes for the
        samples).
    """
    try:
        circle = build("circle")
    except IllConditionedBasis as error:
        why = f"the circle basis is degenerate on this aperture ({error})"
    else:
        gain, kappa = circle.diagnostics.noise_gain, circle.diagnostics.gram_condition
        shown_gain, shown_limit = distinct_figures(gain, AUTO_MAX_NOISE_GAIN)
        if gain <= AUTO_MAX_NOISE_GAIN:
            return _with_reason(
                circle, f"circle basis well conditioned on this aperture: noise gain {shown_gain} "
                f"<= {shown_limit} (kappa(G) {kappa:.3g})",
            )
        why = (f"circle basis ill-conditioned on this aperture: noise gain {shown_gain} > "
               f"{shown_limit} (kappa(G) {kappa:.3g})")
    if aperture.topology is not Topology.UNSUPPORTED:
        mapped = build("csf-qcm")
        return _with_reason(
            mapped, f"{why}; csf-qcm maps the aperture onto the unit "
            f"{'disk' if mapped.basis.annular_obscuration is None else 'annulus'}, where the modes "
            f"are orthogonal (noise gain {mapped.diagnostics.noise_gain:.3g})",
        )
    fallback = build("qr")
    return _with_reason(
        fallback, f"{why}; the aperture ({aperture.describe()}) cannot be mapped, so the modes "
        "are orthonormalised on its samples (qr)",
    )


def _try(build: BuildOne, method: str, **overrides: object) -> Fitter | None:
    try:
        return build(method, **overrides)
    except (IllConditionedBasis, UnsupportedAperture):
        return None


def advised_error(
    error: IllConditionedBasis, build: BuildOne, method: str, aperture: Aperture, modes: int
) -> IllConditionedBasis:
    """The failure of ``method`` with advice that was checked to work on this aperture.

    Two remedies are tried, each by building the fitter it names: the ``csf-qcm`` mapped basis
    (for another method, on an aperture a map can handle) and, with the same method, the largest
    leading mode count that the failed factorisation says is well conditioned (noise gain at most
    ``AUTO_MAX_NOISE_GAIN``, :func:`~wavestack.pipeline.fit.orthonormal.usable_mode_count`). Only those that
    build are suggested; when none does, the message says so.

    Parameters
    ----------
    error : IllConditionedBasis
        The failure (its ``usable_modes`` is the mode count to try).
    build : callable
        ``build(method, modes=...)`` builds one concrete fitter.
    method : str
        The method that failed.
    aperture : Aperture
    modes : int
        The mode count that failed.

    Returns
    -------
    IllConditionedBasis
        The same message with the advice appended, and ``advice`` as (setting, value) pairs.
    """
    advice: list[tuple[str, object]] = []
    words: list[str] = []
    if method != "csf-qcm" and aperture.topology is not Topology.UNSUPPORTED:
        mapped = _try(build, "csf-qcm")
        if mapped is not None:
            advice.append(("method", "csf-qcm"))
            words.append(f"method 'csf-qcm' (checked: kappa(G) {mapped.diagnostics.gram_condition:.3g} "
                         "on this aperture)")
    usable = error.usable_modes
    if usable and usable < modes and _try(build, method, modes=usable) is not None:
        advice.append(("modes", usable))
        words.append(f"at most {usable} modes with method '{method}' (checked; more are ill-conditioned here)")
    text = "; use " + " or ".join(words) if words else "; no other method or mode count was found to work"
    return IllConditionedBasis(f"{error}{text}", usable_modes=usable, advice=tuple(advice))
