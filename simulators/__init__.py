"""Simulated instruments: each device seen from the other end of the wire.

Filled by the instrument issues; a simulator re-implements the device side from the protocol
description and never imports the driver's parser.
"""
