"""Job-level safety: each rule refuses on its own, and a job within every rule passes."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.polish.job_checks import JobRules, JobUnsafe, check_job
from wavestack.polish.measurement import ApertureKey, average_surface
from wavestack.station import MapSample

RULES = JobRules(max_removal_nm=100.0, max_total_dwell_s=50.0, freshness_s=10.0)


def _measurement(mask: np.ndarray, t_ns: int = 0):
    waves = np.where(mask, 0.0, np.nan)
    return average_surface([MapSample(waves, True, None, 0, t_ns)] * 2, wavelength_nm=600.0, reflection_factor=2.0,
                           min_count=2)


def _mask(size: int = 10) -> np.ndarray:
    mask = np.zeros((16, 16), bool)
    mask[2:2 + size, 3:3 + size] = True
    return mask


@pytest.mark.parametrize("rule", ["ok", "nan-dwell", "negative-dwell", "total", "depth", "nan-removal",
                                  "job-aperture", "campaign-aperture", "stale"])
def test_each_rule(rule: str) -> None:
    mask = _mask()
    m = _measurement(mask, t_ns=0)
    dwell = np.zeros((16, 16))
    dwell[4:8, 4:8] = 2.0  # 32 s
    removal = np.full((16, 16), 40.0)
    job, campaign, now = m.aperture, m.aperture, int(5e9)
    words = {"nan-dwell": "finite", "negative-dwell": ">= 0", "total": "max_total_dwell_s", "depth": "deep",
             "nan-removal": "finite", "job-aperture": "job's aperture", "campaign-aperture": "campaign",
             "stale": "freshness_s"}
    if rule == "nan-dwell":
        dwell[0, 0] = np.nan
    elif rule == "negative-dwell":
        dwell[0, 0] = -0.1
    elif rule == "total":
        dwell[0, :] = 2.0  # 32 + 32 s
    elif rule == "depth":
        removal[5, 5] = 100.5
    elif rule == "nan-removal":
        removal[5, 5] = np.inf
    elif rule == "job-aperture":
        job = ApertureKey.of(_mask(9))
    elif rule == "campaign-aperture":
        campaign = ApertureKey.of(_mask(9))
    elif rule == "stale":
        now = int(10.5e9)
    kwargs = {"dwell_s": dwell, "removal_nm": removal, "job_aperture": job, "measurement": m,
              "campaign_aperture": campaign, "now_ns": now}
    if rule == "ok":
        check_job(RULES, **kwargs)
        return
    with pytest.raises(JobUnsafe, match=words[rule]):
        check_job(RULES, **kwargs)
