"""A small polishing-station model: removal commands change a simulated surface.

The simulated PLC drives this model, so that a closed loop (measure surface -> fit Zernike terms ->
command removal -> surface changes) can be exercised end to end and converge. The surface is kept
as Zernike coefficients only (Noll indices 1..n, rms-normalised, surface height in nm), which is
all the loop sees after the fit.

Model of one command with ``removal_nm = r`` and ``passes = p`` (the command's total removal is
split evenly over its passes), for every term ``j`` and every pass::

    c_j <- c_j - efficiency * (1 + efficiency_spread * u_j) * r_j / p + noise_nm * g_j

with ``u_j`` uniform on [-1, 1] and ``g_j`` standard normal, drawn afresh per term and per pass.
The spread models the tool's influence function not matching the commanded shape exactly; the
noise models mid-spatial roughness and tool wear, so polishing never reaches a perfect surface.
With ``passes = 1`` one command removes ``efficiency * (1 +/- spread) * r``. In coefficient
space a removal may have either sign: removing ``-Z_j`` is a removal map shaped like ``-Z_j``
plus piston, which a real tool can produce.

Since issue 14 the simulated PLC no longer polishes with commands: removal happens only through
jobs (:mod:`.machine`), and the command block only publishes the measured terms for the machine's
display. The PLC therefore calls :meth:`PolishingStation.display`, which checks the command and
records the displayed terms, and never :meth:`PolishingStation.apply`; ``apply`` stays as the
standalone coefficient model it was (its own tests use it), changing no surface the camera sees.

A command takes effect once per ``command_id``; applying an id again returns the stored
:class:`PolishingPass` and leaves the surface alone (the PLC handshake retries rely on it). Only the
newest :data:`REMEMBERED_COMMANDS` ids are remembered, so memory stays bounded in a long run.

References
----------
.. [1] R. J. Noll, "Zernike polynomials and atmospheric turbulence", J. Opt. Soc. Am. 66,
   207-211 (1976): index convention and rms normalisation.
.. [2] R. A. Jones, "Computer-controlled optical surfacing with orbital tool motion",
   Opt. Eng. 25, 785-790 (1986): removal = dwell time x influence function (Preston's law),
   the basis of a removal efficiency below one and of its spread.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.simulators._checks import is_integer, is_number, read_only_copy

__all__ = ["MAX_COMMAND_ID", "MAX_PASSES", "PolishingPass", "PolishingStation", "RemovalCommand"]

_log = logging.getLogger(__name__)

MAX_COMMAND_ID = 2**32 - 1  # command ids travel as a uint32 (two Modbus registers)
MAX_PASSES = 100
#: Commands remembered for "once per id" (the newest; a long run must not grow without bound, and
#: ids wrap: the PLC's 16-bit id comes back after 65535 commands and must polish again).
REMEMBERED_COMMANDS = 1024


@dataclass(frozen=True)
class RemovalCommand:
    """One removal order as the PLC receives it.

    Parameters
    ----------
    command_id
        Handshake id, ``0 <= command_id <= 2**32 - 1``; a command takes effect once per id.
    removal_nm
        Requested removal per Zernike term (Noll 1..n, rms-normalised), surface nm, shape
        (n_terms,); stored as a tuple of floats.
    passes
        Number of polishing passes the removal is spread over, ``1 <= passes <= 100``.

    Ranges are checked by :meth:`PolishingStation.validate`, not here, so that a PLC can receive
    any register contents and answer a bad one with an exception code.
    """

    command_id: int
    removal_nm: tuple[float, ...]
    passes: int = 1

    def __post_init__(self) -> None:
        try:
            removal = np.asarray(self.removal_nm, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"RemovalCommand: removal_nm must be numbers, got {self.removal_nm!r}") from exc
        if removal.ndim != 1:
            raise ValueError(
                f"RemovalCommand: removal_nm must be 1-D (one value per term), got shape {removal.shape}"
            )
        object.__setattr__(self, "removal_nm", tuple(float(v) for v in removal))


@dataclass(frozen=True, eq=False)
class PolishingPass:
    """What one command did to the surface (arrays read-only, shape (n_terms,), surface nm).

    Attributes
    ----------
    command_id
        The command's id.
    surface_before_nm, surface_after_nm
        Zernike coefficients before and after the command.
    removed_nm
        ``surface_before_nm - surface_after_nm`` (includes the process noise).
    """

    command_id: int
    surface_before_nm: NDArray[np.float64]
    surface_after_nm: NDArray[np.float64]
    removed_nm: NDArray[np.float64]


def _check_number(name: str, value: float, low: float, high: float, *, low_open: bool = False) -> float:
    """``value`` as float if in range (``low < value`` when ``low_open``), else ValueError naming it."""
    if not is_number(value):
        raise ValueError(f"PolishingStation: {name} must be a number, got {value!r}")
    number = float(value)
    ok = math.isfinite(number) and (low < number if low_open else low <= number) and number <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise ValueError(f"PolishingStation: {name} must lie in {bracket}{low:g}, {high:g}], got {value!r}")
    return number


def _check_command_id(command_id: object) -> None:
    if not (is_integer(command_id) and 0 <= int(command_id) <= MAX_COMMAND_ID):  # type: ignore[call-overload]
        raise ValueError(
            f"PolishingStation: command_id must be an integer in [0, {MAX_COMMAND_ID}], got {command_id!r}"
        )


class PolishingStation:
    """Simulated polishing machine holding a surface as Zernike coefficients.

    Parameters
    ----------
    initial_surface_nm
        Surface, shape (n_terms,), Noll 1..n, rms-normalised, surface nm; finite.
    efficiency
        Mean fraction of the commanded removal actually removed, in (0, 1].
    efficiency_spread
        Relative half-width of the uniform per-term, per-pass efficiency scatter, in [0, 1).
    noise_nm
        Standard deviation of the Gaussian process noise added to every term per pass, nm, >= 0.
    max_removal_nm
        Largest ``|removal_nm|`` per term one command may request, nm, > 0.
    seed
        Seed of the station's own random generator (same seed and commands, same surfaces).

    Raises
    ------
    ValueError
        A parameter out of range, naming it and the range.

    Notes
    -----
    Thread-safe: a Modbus server thread may :meth:`apply` while a test reads :attr:`surface_nm`.
    """

    def __init__(
        self,
        initial_surface_nm: ArrayLike,
        *,
        efficiency: float = 0.8,
        efficiency_spread: float = 0.05,
        noise_nm: float = 0.5,
        max_removal_nm: float = 500.0,
        seed: int = 0,
    ) -> None:
        try:
            surface = np.array(initial_surface_nm, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"PolishingStation: initial_surface_nm must be numbers, got {initial_surface_nm!r}"
            ) from exc
        if surface.ndim != 1 or surface.size == 0 or not np.all(np.isfinite(surface)):
            raise ValueError(
                f"PolishingStation: initial_surface_nm must be a finite 1-D array of Zernike terms, "
                f"got shape {surface.shape}"
            )
        self._efficiency = _check_number("efficiency", efficiency, 0.0, 1.0, low_open=True)
        self._spread = _check_number("efficiency_spread", efficiency_spread, 0.0, math.nextafter(1.0, 0.0))
        self._noise_nm = _check_number("noise_nm", noise_nm, 0.0, math.inf)
        self._max_removal_nm = _check_number("max_removal_nm", max_removal_nm, 0.0, math.inf, low_open=True)
        self._surface = surface
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._done: OrderedDict[int, tuple[RemovalCommand, PolishingPass]] = OrderedDict()
        self._last_command_id: int | None = None
        self._passes_applied = 0
        self._displayed: tuple[int, tuple[float, ...]] | None = None
        self._displays = 0

    # ------------------------------------------------------------------------------ state
    @property
    def n_terms(self) -> int:
        """Number of Zernike terms n."""
        return int(self._surface.shape[0])

    @property
    def surface_nm(self) -> NDArray[np.float64]:
        """Copy of the current surface, shape (n_terms,), surface nm."""
        with self._lock:
            return self._surface.copy()

    @property
    def passes_applied(self) -> int:
        """Polishing passes run so far (sum of ``passes`` over the distinct commands applied)."""
        with self._lock:
            return self._passes_applied

    @property
    def last_command_id(self) -> int | None:
        """Id of the last command that took effect (None before the first)."""
        with self._lock:
            return self._last_command_id

    @property
    def max_removal_nm(self) -> float:
        """Largest ``|removal_nm|`` per term one command may request, nm."""
        return self._max_removal_nm

    @property
    def displayed(self) -> tuple[int, tuple[float, ...]] | None:
        """The last command shown on the machine's display: its id and terms (nm); None before the first."""
        with self._lock:
            return self._displayed

    @property
    def displays(self) -> int:
        """Commands shown on the display (each accepted command id once)."""
        with self._lock:
            return self._displays

    # ------------------------------------------------------------------------------ verbs
    def display(self, command: RemovalCommand) -> None:
        """Check a command (:meth:`validate`) and show its terms on the display; the surface is unchanged.

        Raises
        ------
        ValueError
            From :meth:`validate`; nothing is shown.
        """
        self.validate(command)
        with self._lock:
            self._displayed = (int(command.command_id), tuple(command.removal_nm))
            self._displays += 1

    def validate(self, command: RemovalCommand) -> None:
        """Check a command's parameters against the station's ranges.

        Raises
        ------
        ValueError
            Naming the parameter and its allowed range: ``command_id`` in [0, 2**32 - 1],
            ``passes`` in [1, 100], ``removal_nm`` of length n_terms with every term finite and
            within [-max_removal_nm, max_removal_nm].
        """
        _check_command_id(command.command_id)
        passes = command.passes
        if not (is_integer(passes) and 1 <= passes <= MAX_PASSES):
            raise ValueError(
                f"PolishingStation: passes must be an integer in [1, {MAX_PASSES}], got {passes!r}"
            )
        removal = np.asarray(command.removal_nm, dtype=np.float64)
        if removal.shape != (self.n_terms,):
            raise ValueError(
                f"PolishingStation: removal_nm must hold {self.n_terms} terms (Noll 1..{self.n_terms}), "
                f"got {removal.size}"
            )
        bad = np.flatnonzero(~(np.abs(removal) <= self._max_removal_nm))
        if bad.size:
            raise ValueError(
                f"PolishingStation: removal_nm must lie in "
                f"[-{self._max_removal_nm:g}, {self._max_removal_nm:g}] nm "
                f"on every term; Noll terms {(bad + 1).tolist()} have {removal[bad].tolist()}"
            )

    def apply(self, command: RemovalCommand) -> PolishingPass:
        """Run a command once: polish ``passes`` passes and return what changed.

        Parameters
        ----------
        command
            The removal order. A ``command_id`` seen before returns that earlier pass unchanged
            and does not touch the surface (even if the other fields differ).

        Returns
        -------
        PolishingPass
            Surface before and after, and the removal actually achieved (nm).

        Raises
        ------
        ValueError
            From :meth:`validate` for a new command id; the surface is then unchanged.
        """
        _check_command_id(command.command_id)
        with self._lock:
            earlier = self._done.get(int(command.command_id))
            if earlier is not None:
                earlier_command, earlier_pass = earlier
                if command != earlier_command:
                    _log.warning(
                        "polishing command %d repeated with different parameters; ignored (once per id)",
                        command.command_id,
                    )
                return earlier_pass
            self.validate(command)
            removal = np.asarray(command.removal_nm, dtype=np.float64)
            before = self._surface.copy()
            after = before.copy()
            per_pass = removal / command.passes
            for _ in range(command.passes):
                scatter = self._rng.uniform(-1.0, 1.0, self.n_terms)
                noise = self._rng.standard_normal(self.n_terms)
                after -= self._efficiency * (1.0 + self._spread * scatter) * per_pass
                after += self._noise_nm * noise
            command_id = int(command.command_id)
            result = PolishingPass(
                command_id=command_id,
                surface_before_nm=read_only_copy(before),
                surface_after_nm=read_only_copy(after),
                removed_nm=read_only_copy(before - after),
            )
            self._done[command_id] = (command, result)
            self._done.move_to_end(command_id)
            while len(self._done) > REMEMBERED_COMMANDS:
                self._done.popitem(last=False)
            self._surface = after
            self._last_command_id = command_id
            self._passes_applied += int(command.passes)
        _log.debug(
            "polishing command %d: %d pass(es), rms of terms >= 4 %.3g -> %.3g nm",
            command.command_id,
            command.passes,
            float(np.sqrt(np.sum(before[3:] ** 2))),
            float(np.sqrt(np.sum(after[3:] ** 2))),
        )
        return result
