"""Three real cameras' GenApi XML and the simulated cameras that serve them (shared by the tests)."""

from __future__ import annotations

from pathlib import Path

from shared_data import DATA

GENICAM = DATA / "external" / "genicam"
#: personality name -> the vendor's XML file
VENDOR_XML: dict[str, Path] = {
    "flir-bfs": GENICAM / "flir_blackflys_bfs-u3-161s7m_adgenicam.xml",
    "alvium-1800u": GENICAM / "alliedvision_alvium_1800u-811m_adgenicam.xml",
    "basler-ace-gige": GENICAM / "basler_ace_aca1920-25gm_gige_adgenicam.xml",
}
#: a pixel format each offers besides its power-on one, and an exposure its registers hold exactly, µs
SETTINGS = {"flir-bfs": ("Mono16", 2500.0), "alvium-1800u": ("Mono8", 1234.5), "basler-ace-gige": ("Mono8", 2460.0)}
