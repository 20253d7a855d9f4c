"""Device drivers: bytes and devices, nothing about Zernike terms.

Filled by the instrument issues (camera, phase shifter, PLC link).
"""
