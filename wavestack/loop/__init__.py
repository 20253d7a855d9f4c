"""The loop kernel: what every closed loop (polishing, alignment) shares.

A loop's machine as data (:class:`StateTable`: the expected transitions, the terminal phases, a
fault and a stop everywhere, an unexpected event faulting), the one runner that drives it
(:func:`run_machine`, with :class:`Transitions` noting every state entered), the campaign record
with the station recording's integrity (:class:`CampaignWriter`, :func:`read_campaign`: a CRC-32
per record, an exclusive create, a reader that never waits and returns what is intact), and the
history table the readers above the loops take (:class:`LoopHistory`).

The loops stand side by side on this kernel and on the station service (``wavestack.station``);
none imports another.
"""

from __future__ import annotations

from wavestack.loop.history import Cell, LoopHistory
from wavestack.loop.record import CAMPAIGN_VERSION, MAP_KIND, CampaignEntry, CampaignLog, CampaignWriter, read_campaign
from wavestack.loop.runner import EventRecord, Transitions, run_machine
from wavestack.loop.table import StateTable, Step

__all__ = ["CAMPAIGN_VERSION", "MAP_KIND", "CampaignEntry", "CampaignLog", "CampaignWriter", "Cell", "EventRecord", "LoopHistory", "StateTable",
           "Step", "Transitions", "read_campaign", "run_machine"]
