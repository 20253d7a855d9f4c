"""The station: streaming devices -> live refits -> results, recording and outputs (filled by the station issue)."""
