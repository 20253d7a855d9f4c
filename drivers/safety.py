"""The safety stage every actuator output passes: drive limits, rate limit, invalid-input action.

A closed loop (measured surface -> fit -> removal or voltage command) must never send a value the
hardware should not see, whatever the fit, the network or the clock did. :class:`SafetyStage` sits
between the loop and every driver; it is a pure object (no I/O, no clock of its own: the caller
passes the times in), so every rule is testable without a wire. Its configuration,
:class:`SafetyLimits`, is validated in :mod:`wavestack.drivers.safety_limits` and re-exported here.

It follows the processing of the EPICS analog output (ao) record [1]_, per channel:

1. *Invalid output action* (ao fields ``IVOA``/``IVOV``, menu ``menuIvoa`` [2]_): if the request
   is invalid (flagged invalid by the caller, missing, non-finite anywhere, or stale), it is not
   forwarded. ``invalid_action="hold"`` is EPICS's "Don't drive outputs" (the last output stays);
   ``"safe_value"`` is "Set output to IVOV", except that the move toward ``safe_value`` is itself
   rate limited (EPICS writes IVOV at once; a mirror or a polishing head must not jump).
2. *Drive limits* (``DRVL``/``DRVH``): the request is clipped to ``[lower, upper]`` inclusive.
3. *Limit rate of change* (``OROC``): the output differs from the previous output by at most
   ``max_step`` per update. Unlike ``OROC = 0`` in EPICS, the rate limit cannot be switched off.

The stage additionally guarantees what EPICS leaves to floating point: every output lies in
``[lower, upper]`` and every step is ``<= max_step`` when both are evaluated in float64, whatever
the inputs were (a last-ulp overshoot of ``last + step`` is pulled back toward the last output).

References
----------
.. [1] EPICS Base Record Reference, "Analog Output Record (ao)": sections "Drive Limits" and
   "Limit Rate of Change" (fields DRVH, DRVL, OROC, OVAL), and the alarm parameters IVOA, IVOV.
   https://docs.epics-controls.org/projects/base/en/latest/aoRecord.html
.. [2] EPICS Base Record Reference, "Menu menuIvoa": "Continue normally", "Don't drive outputs",
   "Set output to IVOV".
"""

from __future__ import annotations

import enum
import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.drivers._checks import read_only_copy
from wavestack.drivers.safety_limits import InvalidAction as InvalidAction  # re-exported
from wavestack.drivers.safety_limits import SafetyLimits

__all__ = ["SafeOutput", "SafetyLimits", "SafetyStage", "SafetyStatus"]

_log = logging.getLogger(__name__)

# A last-ulp overshoot needs at most a couple of nextafter nudges; the bound keeps the loop finite.
_MAX_NUDGES = 8


class SafetyStatus(enum.Flag):
    """What the safety stage did to one request (flags combine, e.g. ``STALE | HELD``).

    ``OK``: forwarded unchanged. ``CLIPPED``: clipped to the drive limits. ``RATE_LIMITED``: the
    change from the last output was cut to ``max_step`` on some channel. ``NON_FINITE``: NaN or inf
    in the request. ``STALE``: the measurement behind the request is too old (or from the future).
    ``INVALID``: the caller marked the request invalid or gave none. ``HELD``: the request was not
    forwarded; the output held still (``"hold"``) or moved toward ``safe_value``.
    """

    OK = 0
    CLIPPED = enum.auto()
    RATE_LIMITED = enum.auto()
    NON_FINITE = enum.auto()
    STALE = enum.auto()
    INVALID = enum.auto()
    HELD = enum.auto()


@dataclass(frozen=True, eq=False)
class SafeOutput:
    """The value the stage lets through for one update.

    Attributes
    ----------
    values
        Output to send, shape (n,), read-only; always within the limits.
    status
        :class:`SafetyStatus` flags; ``SafetyStatus.OK`` when the request passed unchanged.
    reason
        Human-readable explanation when ``status`` is not OK, else None.
    requested
        Read-only copy of the request as given, shape (n,), or None if there was none.
    """

    values: NDArray[np.float64]
    status: SafetyStatus
    reason: str | None
    requested: NDArray[np.float64] | None

    @property
    def forwarded(self) -> bool:
        """True if the request (possibly clipped or rate limited) was acted on, False if held."""
        return SafetyStatus.HELD not in self.status


def _channels(mask: NDArray[np.bool_]) -> list[int]:
    return np.flatnonzero(mask).tolist()


class SafetyStage:
    """Stateful filter between a closed loop and one actuator (see the module docstring).

    Parameters
    ----------
    limits
        The channel limits; the initial output is ``limits.safe_value``.

    Notes
    -----
    Not thread-safe: one owner (the station's loop) calls :meth:`update`, or :meth:`propose` and
    :meth:`commit`. The stage does no I/O: :meth:`propose` never changes the last output, so an
    output that may be refused proposes, sends, and commits only what was acknowledged.

    Examples
    --------
    One channel, 0..10 V, at most 1 V per update; a request of 5 V moves the output from the
    safe value 0 V by one step, and a stale request holds it there:

    >>> stage = SafetyStage(SafetyLimits(lower=[0.0], upper=[10.0], max_step=1.0, max_age_s=0.5))
    >>> out = stage.update([5.0], measured_at_s=0.0, now_s=0.1)
    >>> out.values.tolist(), out.status == SafetyStatus.RATE_LIMITED
    ([1.0], True)
    >>> out = stage.update([5.0], measured_at_s=0.0, now_s=1.0)
    >>> out.values.tolist(), out.forwarded, out.status == SafetyStatus.STALE | SafetyStatus.HELD
    ([1.0], False, True)
    """

    def __init__(self, limits: SafetyLimits) -> None:
        self._limits = limits
        self._last = limits.safe_value.copy()
        self._holding = False

    @property
    def limits(self) -> SafetyLimits:
        """The limits this stage enforces."""
        return self._limits

    @property
    def last_output(self) -> NDArray[np.float64]:
        """Copy of the last output, shape (n,) (``safe_value`` before the first update)."""
        return self._last.copy()

    def commit(self, values: ArrayLike) -> None:
        """Record what the actuator really holds now: a proposal it acknowledged (see :meth:`propose`).

        Same checks as :meth:`reset`; the rate limit of the next proposal counts from ``values``.
        """
        self.reset(values)

    def reset(self, values: ArrayLike) -> None:
        """Set the last output, e.g. to the actuator's read-back after a reconnect.

        Parameters
        ----------
        values
            Shape (n,), finite and within ``[lower, upper]``.

        Raises
        ------
        ValueError
            Wrong shape, non-finite or outside the limits; the last output is then unchanged.
        """
        arr = self._as_request(values, "values")
        lim = self._limits
        bad = ~np.isfinite(arr) | (arr < lim.lower) | (arr > lim.upper)
        if bad.any():
            raise ValueError(
                f"SafetyStage.reset: values must be finite and within [lower, upper]; channels "
                f"{_channels(bad)} have {arr[bad].tolist()}"
            )
        self._last = arr
        self._holding = False

    def update(
        self,
        requested: ArrayLike | None,
        *,
        valid: bool = True,
        measured_at_s: float,
        now_s: float,
        reason: str | None = None,
    ) -> SafeOutput:
        """:meth:`propose`, then take the proposal as the last output at once (an actuator that cannot refuse).

        For an output that can refuse or lose a command (a PLC), use :meth:`propose` and
        :meth:`commit` only what the actuator acknowledged.
        """
        out = self.propose(requested, valid=valid, measured_at_s=measured_at_s, now_s=now_s, reason=reason)
        self._last = np.array(out.values)
        return out

    def propose(
        self,
        requested: ArrayLike | None,
        *,
        valid: bool = True,
        measured_at_s: float,
        now_s: float,
        reason: str | None = None,
    ) -> SafeOutput:
        """Filter one request and return what may be sent to the actuator; the last output stays.

        The proposal counts from the last *committed* output (:meth:`commit`, :meth:`reset`), so a
        command the actuator refused or lost never moves the base of the rate limit.

        Parameters
        ----------
        requested
            Requested output, shape (n,), actuator units; None when the loop has nothing (treated
            as invalid).
        valid
            False when the loop knows the request is bad (failed fit, saturated frame, ...).
        measured_at_s
            Time of the measurement the request derives from, s, on the caller's clock.
        now_s
            Current time on the same clock, s.
        reason
            Why the caller marked the request invalid; quoted in the output's ``reason``.

        Returns
        -------
        SafeOutput
            Values within the limits, differing from the last output by at most ``max_step``.
            Invalid input (not forwarded) keeps the last output under ``"hold"``.

        Raises
        ------
        ValueError
            ``requested`` is not shape (n,) (a programming error); nothing changes.
        """
        lim = self._limits
        request = None if requested is None else self._as_request(requested, "requested")
        status, reasons = _screen_request(request, valid, reason)
        stale_reason = _staleness(lim, measured_at_s, now_s)
        if stale_reason is not None:
            status |= SafetyStatus.STALE
            reasons.append(stale_reason)

        if status != SafetyStatus.OK:
            values, action, action_reasons = _invalid_output(lim, self._last)
            if not self._holding:
                _log.warning("safety stage stops forwarding: %s", "; ".join(reasons + action_reasons))
            self._holding = True
        else:
            assert request is not None  # a missing request always sets INVALID above
            values, action, action_reasons = _drive(lim, self._last, request)
            if self._holding:
                _log.info("safety stage forwards requests again")
            self._holding = False
        status |= action
        reasons.extend(action_reasons)
        return SafeOutput(
            values=read_only_copy(values),
            status=status,
            reason="; ".join(reasons) if reasons else None,
            requested=None if request is None else read_only_copy(request),
        )

    # ------------------------------------------------------------------------------- private
    def _as_request(self, value: ArrayLike, name: str) -> NDArray[np.float64]:
        n = self._limits.n_channels
        try:
            arr = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"SafetyStage: {name} must be {n} numbers, got {value!r}") from exc
        if arr.shape != (n,):
            raise ValueError(f"SafetyStage: {name} must have shape ({n},), got {arr.shape}")
        return arr


# ------------------------------------------------------------------ the ao-record stages, pure
def _screen_request(
    request: NDArray[np.float64] | None, valid: bool, reason: str | None
) -> tuple[SafetyStatus, list[str]]:
    """Reject a missing, non-finite or caller-invalidated request: the flags and reasons (IVOA input)."""
    status = SafetyStatus.OK
    reasons: list[str] = []
    if request is None:
        status |= SafetyStatus.INVALID
        reasons.append("no request" + (f" ({reason})" if reason else ""))
        return status, reasons
    non_finite = ~np.isfinite(request)
    if non_finite.any():
        status |= SafetyStatus.NON_FINITE
        reasons.append(f"non-finite request on channels {_channels(non_finite)}")
    if not valid:
        status |= SafetyStatus.INVALID
        reasons.append("request marked invalid" + (f" ({reason})" if reason else ""))
    return status, reasons


def _staleness(limits: SafetyLimits, measured_at_s: float, now_s: float) -> str | None:
    """Why the measurement time makes the request stale, or None if it is fresh."""
    try:
        measured, now = float(measured_at_s), float(now_s)
    except (TypeError, ValueError):
        return f"timestamps not numbers (measured_at_s={measured_at_s!r}, now_s={now_s!r})"
    if not (math.isfinite(measured) and math.isfinite(now)):
        return f"timestamps not finite (measured_at_s={measured}, now_s={now})"
    age = now - measured
    if age > limits.max_age_s:
        return f"input stale: measured {age:.3g} s ago, max_age_s={limits.max_age_s:g}"
    if -age > limits.max_future_s:
        return (
            f"input time-stamped {-age:.3g} s in the future "
            f"(clock skew tolerance max_future_s={limits.max_future_s:g})"
        )
    return None


def _invalid_output(
    limits: SafetyLimits, last: NDArray[np.float64]
) -> tuple[NDArray[np.float64], SafetyStatus, list[str]]:
    """The output when a request is not forwarded (IVOA): hold ``last`` or step toward ``safe_value``."""
    status = SafetyStatus.HELD
    if limits.invalid_action == "safe_value":
        values = _step_toward(limits, last, limits.safe_value)
        if not np.array_equal(values, limits.safe_value):
            status |= SafetyStatus.RATE_LIMITED
        return values, status, ["moving toward safe_value"]
    return last.copy(), status, ["holding the last output"]


def _drive(
    limits: SafetyLimits, last: NDArray[np.float64], request: NDArray[np.float64]
) -> tuple[NDArray[np.float64], SafetyStatus, list[str]]:
    """A forwarded request: clip to the drive limits (DRVL/DRVH), then limit the rate (OROC)."""
    status = SafetyStatus.OK
    reasons: list[str] = []
    clipped = np.clip(request, limits.lower, limits.upper)
    was_clipped = clipped != request
    if was_clipped.any():
        status |= SafetyStatus.CLIPPED
        reasons.append(f"clipped to the drive limits on channels {_channels(was_clipped)}")
    values = _step_toward(limits, last, clipped)
    was_limited = values != clipped
    if was_limited.any():
        status |= SafetyStatus.RATE_LIMITED
        reasons.append(f"rate limited to max_step on channels {_channels(was_limited)}")
    return values, status, reasons


def _step_toward(
    limits: SafetyLimits, last: NDArray[np.float64], target: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Move from ``last`` toward ``target`` (within limits) by at most ``max_step``.

    ``target`` must lie in ``[lower, upper]``. Exact in float64: the result lies in
    ``[lower, upper]``, equals ``target`` when ``|target - last| <= max_step``, and
    ``|result - last| <= max_step`` as evaluated in float64 (a rounding overshoot is nudged
    back toward ``last`` one ulp at a time; ``last`` itself satisfies both bounds, so the
    nudging terminates).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        gap = target - last
    # within one step: take the target itself (last + gap can round away from it)
    values = np.where(
        np.abs(gap) <= limits.max_step,
        target,
        np.clip(last + np.clip(gap, -limits.max_step, limits.max_step), limits.lower, limits.upper),
    )
    for _ in range(_MAX_NUDGES):
        over = np.abs(values - last) > limits.max_step
        if not over.any():
            return values
        values = np.where(over, np.nextafter(values, last), values)
    # Unreachable for finite limits (one or two ulps at most); never emit an unchecked value.
    over = np.abs(values - last) > limits.max_step
    return np.where(over, last, values)
