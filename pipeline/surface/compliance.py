"""Pass or fail against the drawing: each toleranced quantity, and the one that limits.

A quantity passes when its figure is within its limit (``|SAG| <= A``; ``IRR <= B``,
``RSI <= C``, ``RMSx <= D``). The limiting quantity is the one closest to, or furthest over,
its limit: the largest ratio of figure to limit. Figures and limits are compared in nm of
surface height, so a drawing at 546.07 nm and a measurement at 632.8 nm compare correctly.
"""

from __future__ import annotations

from dataclasses import dataclass

from .form import FormFigures
from .fringes import fringe_nm
from .tolerance import FormTolerance

__all__ = ["QuantityCheck", "SpecVerdict", "check_form"]


@dataclass(frozen=True)
class QuantityCheck:
    """One toleranced quantity against its limit.

    Attributes
    ----------
    quantity : str
        ``"SAG"``, ``"IRR"``, ``"RSI"``, ``"RMSt"``, ``"RMSi"`` or ``"RMSa"``.
    measured_nm : float
        The figure (SAG signed), nm.
    limit_nm : float
        The largest allowed value, nm.
    """

    quantity: str
    measured_nm: float
    limit_nm: float

    @property
    def ratio(self) -> float:
        """``|measured| / limit``: <= 1 passes."""
        return abs(self.measured_nm) / self.limit_nm

    @property
    def passed(self) -> bool:
        """Whether the figure is within its limit."""
        return abs(self.measured_nm) <= self.limit_nm


@dataclass(frozen=True)
class SpecVerdict:
    """A measured surface against a drawing's form tolerance.

    Attributes
    ----------
    tolerance : FormTolerance
    checks : tuple of QuantityCheck
        One per toleranced quantity, in the drawing's order.
    """

    tolerance: FormTolerance
    checks: tuple[QuantityCheck, ...]

    @property
    def passed(self) -> bool:
        """Every toleranced quantity within its limit."""
        return all(check.passed for check in self.checks)

    @property
    def limiting(self) -> QuantityCheck:
        """The check with the largest figure-to-limit ratio."""
        return max(self.checks, key=lambda check: check.ratio)

    def summary(self) -> str:
        """One line, e.g. ``"3/2(0.5/0.2): FAIL, limiting IRR 0.62 > 0.5 fringes at 546.07 nm"``."""
        limiting = self.limiting
        scale = fringe_nm(self.tolerance.wavelength_nm)
        relation = "<=" if limiting.passed else ">"
        return (f"{self.tolerance.notation}: {'PASS' if self.passed else 'FAIL'}, limiting {limiting.quantity} "
                f"{abs(limiting.measured_nm) / scale:.3g} {relation} {limiting.limit_nm / scale:.3g} fringes "
                f"at {self.tolerance.wavelength_nm:g} nm")

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: the tolerance, pass/fail, the limiting quantity and every check (nm and fringes)."""
        scale = fringe_nm(self.tolerance.wavelength_nm)
        return {
            **self.tolerance.as_dict(), "passed": self.passed, "limiting": self.limiting.quantity,
            "checks": [{"quantity": c.quantity, "measured_nm": c.measured_nm, "limit_nm": c.limit_nm,
                        "measured_fringes": c.measured_nm / scale, "limit_fringes": c.limit_nm / scale,
                        "ratio": c.ratio, "passed": c.passed} for c in self.checks],
        }


def check_form(form: FormFigures, tolerance: FormTolerance) -> SpecVerdict:
    """Check form figures against a tolerance.

    Examples
    --------
    >>> from wavestack.pipeline.surface import parse_form_tolerance
    >>> form = FormFigures(sag_nm=-300.0, irr_nm=120.0, rsi_nm=20.0, rmst_nm=90.0, rmsi_nm=25.0,
    ...                    rmsa_nm=24.0, pv_nm=420.0)
    >>> verdict = check_form(form, parse_form_tolerance("3/1(0.5/0.2)"))
    >>> verdict.passed, verdict.limiting.quantity
    (False, 'SAG')
    """
    figures = form.by_quantity()
    return SpecVerdict(tolerance=tolerance, checks=tuple(
        QuantityCheck(quantity=name, measured_nm=figures[name], limit_nm=limit)
        for name, limit in tolerance.limits_nm().items()))
