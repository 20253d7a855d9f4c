"""Simulated benches: the instruments wired to one test optic, as on a real interferometer table.

On a real bench the camera sees the fringes that the piezo's position produces. Here the same
coupling is explicit: the simulated camera's renderer asks the simulated MDT693B for its output
voltage, turns it into a phase shift with the bench's *true* calibration (which need not equal the
calibration in the station's config — that is how a miscalibrated piezo is simulated), and renders
the test optic at the camera's device time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from numpy.typing import NDArray

from wavestack.simulators.mdt693b.device import MDT693BDevice
from wavestack.simulators.optic import OpticTruth, TestOptic
from wavestack.simulators.spots import SpotRenderer
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

@dataclass(frozen=True)
class PiezoCoupling:
    """How the piezo moves the fringes on this bench.

    Attributes
    ----------
    axis : str
        The controller output driving the reference mirror ("x", "y" or "z").
    radians_per_volt : float
        True phase shift per volt (double pass included).
    """

    axis: str = "x"
    radians_per_volt: float = 0.05


@dataclass(frozen=True, eq=False)
class FrameTruth:
    """Ground truth kept by the simulated camera for each block id."""

    optic: OpticTruth | Any
    pzt_voltage_v: float | None
    phase_shift_rad: float


class SimulatedInterferometer:
    """A simulated camera (USB3 Vision over a pyusb backend) looking at a test optic through a piezo.

    Parameters
    ----------
    optic : TestOptic
        The test optic; its bit depth should match the camera's pixel format.
    camera_settings : U3VSimSettings
        The camera; its width and height must match the optic's frame shape.
    piezo : MDT693BDevice or None
        The simulated piezo controller (None: no phase shifting, e.g. a carrier station).
    coupling : PiezoCoupling
    """

    def __init__(self, optic: TestOptic, camera_settings: U3VSimSettings, piezo: MDT693BDevice | None = None,
                 coupling: PiezoCoupling = PiezoCoupling()) -> None:
        if optic.shape != (camera_settings.height, camera_settings.width):
            raise ValueError(f"optic frame shape {optic.shape} differs from the camera's "
                             f"{(camera_settings.height, camera_settings.width)}")
        self.optic = optic
        self.piezo = piezo
        self.coupling = coupling
        self.camera = SimulatedU3VCamera(camera_settings, self._render)
        self.backend = SimulatedUsbBackend([self.camera])

    def _render(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[NDArray[Any], FrameTruth]:
        volts = None if self.piezo is None else self.piezo.voltage(self.coupling.axis)
        shift = 0.0 if volts is None else volts * self.coupling.radians_per_volt
        pixels, truth = self.optic.interferogram(device_time_ns * 1e-9, shift)
        return pixels, FrameTruth(truth, volts, shift)


class SimulatedShackHartmann:
    """A simulated camera behind a lenslet array looking at the same kind of test optic."""

    def __init__(self, spots: SpotRenderer, camera_settings: U3VSimSettings) -> None:
        self.spots = spots
        self.camera = SimulatedU3VCamera(camera_settings, self._render)
        self.backend = SimulatedUsbBackend([self.camera])

    def _render(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[NDArray[Any], Any]:
        pixels, truth = self.spots.spot_frame(device_time_ns * 1e-9)
        return pixels, truth

