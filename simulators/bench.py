"""Simulated benches: the instruments wired to one test optic, as on a real interferometer table.

On a real bench the camera sees the fringes that the piezo's position produces. Here the same
coupling is explicit: the simulated camera's renderer asks the simulated MDT693B for its output
voltage, turns it into a phase shift with the bench's *true* calibration (which need not equal the
calibration in the station's config — that is how a miscalibrated piezo is simulated), and renders
the test optic at the camera's device time.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from numpy.typing import NDArray

from wavestack.simulators.mdt693b import MDT693BDevice
from wavestack.simulators.optic import OpticTruth, TestOptic
from wavestack.simulators.spots import SpotRenderer
from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

CameraSettings = U3VSimSettings | GigESimSettings


def _camera(settings: CameraSettings, render: Any) -> tuple[SimulatedU3VCamera | SimulatedGigECamera,
                                                             SimulatedUsbBackend | None]:
    """The simulated camera the settings describe: USB3 Vision on a pyusb backend, or GigE Vision
    (its sockets are bound; :meth:`SimulatedGigECamera.start` serves them)."""
    if isinstance(settings, GigESimSettings):
        return SimulatedGigECamera(settings, render), None
    camera = SimulatedU3VCamera(settings, render)
    return camera, SimulatedUsbBackend([camera])

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
    """Ground truth kept by the simulated camera for each block id.

    The optic's truth (a full wavefront map, 8 MB at 1024 x 1024) is not kept per frame: the
    camera keeps the truth of its last 64 frames, and holding 64 maps cost half a gigabyte. It is
    recomputed on request from the frame's time, which gives the same map as long as neither the
    optic's aperture nor its surface (polished by a simulated machine) has changed since; after a
    change :attr:`optic` is None (unknown, never wrong).

    Attributes
    ----------
    time_s : float
        The optic's time of the frame (drift), seconds.
    pzt_voltage_v : float or None
        The simulated piezo's output when the frame was rendered.
    phase_shift_rad : float
        The phase shift the piezo produced, radians.
    aperture_revision : int
        The optic's aperture revision when the frame was rendered.
    surface_revision : int or None
        The optic's surface revision when the frame was rendered (None: no surface state).
    """

    time_s: float
    pzt_voltage_v: float | None
    phase_shift_rad: float
    aperture_revision: int
    source: TestOptic
    carrier_cycles: tuple[float, float] = (0.0, 0.0)
    vibration_rad: float = 0.0
    surface_revision: int | None = None

    @property
    def optic(self) -> OpticTruth | None:
        """The optic's truth as rendered in this frame (None if its aperture or surface changed since)."""
        if self.source.aperture_revision != self.aperture_revision:
            return None
        surface = self.source.surface
        if (None if surface is None else surface.revision) != self.surface_revision:
            return None
        return dataclasses.replace(self.source.truth(self.time_s), phase_shift_rad=self.phase_shift_rad,
                                   vibration_rad=self.vibration_rad, carrier_cycles=self.carrier_cycles)


class SimulatedInterferometer:
    """A simulated camera (USB3 Vision over a pyusb backend, or GigE Vision on loopback) looking at a
    test optic through a piezo.

    Parameters
    ----------
    optic : TestOptic
        The test optic; its bit depth should match the camera's pixel format.
    camera_settings : U3VSimSettings or GigESimSettings
        The camera and its transport; its width and height must match the optic's frame shape.
        ``backend`` is the pyusb backend of a USB3 Vision camera (None for GigE Vision).
    piezo : MDT693BDevice or None
        The simulated piezo controller (None: no phase shifting, e.g. a carrier station).
    coupling : PiezoCoupling
    """

    def __init__(self, optic: TestOptic, camera_settings: CameraSettings, piezo: MDT693BDevice | None = None,
                 coupling: PiezoCoupling = PiezoCoupling()) -> None:
        if optic.shape != (camera_settings.height, camera_settings.width):
            raise ValueError(f"optic frame shape {optic.shape} differs from the camera's "
                             f"{(camera_settings.height, camera_settings.width)}")
        self.optic = optic
        self.piezo = piezo
        self.coupling = coupling
        self.camera, self.backend = _camera(camera_settings, self._render)

    def _render(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[NDArray[Any], FrameTruth]:
        volts = None if self.piezo is None else self.piezo.voltage(self.coupling.axis)
        shift = 0.0 if volts is None else volts * self.coupling.radians_per_volt
        time_s = device_time_ns * 1e-9
        pixels, facts = self.optic.frame(time_s, shift)  # the truth's map is re-made on request, not per frame
        return pixels, FrameTruth(time_s, volts, shift, facts.aperture_revision, self.optic,
                                  facts.carrier_cycles, facts.vibration_rad, facts.surface_revision)


class SimulatedShackHartmann:
    """A simulated camera behind a lenslet array looking at the same kind of test optic."""

    def __init__(self, spots: SpotRenderer, camera_settings: CameraSettings) -> None:
        self.spots = spots
        self.camera, self.backend = _camera(camera_settings, self._render)

    def _render(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[NDArray[Any], Any]:
        pixels, truth = self.spots.spot_frame(device_time_ns * 1e-9)
        return pixels, truth

