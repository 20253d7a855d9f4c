"""The local cluster runs with less Dask housekeeping (wavestack.batch.cluster.QUIET_CONFIG)."""

from __future__ import annotations

import os

from wavestack.batch.cluster import campaign_client


def _worker_settings() -> dict[str, object]:
    import dask

    return {"profile": dask.config.get("distributed.worker.profile.enabled"),
            "tick": dask.config.get("distributed.admin.tick.interval"),
            "trim": os.environ.get("MALLOC_TRIM_THRESHOLD_")}


def _scheduler_stealing(dask_scheduler) -> bool:  # noqa: ANN001 - distributed passes the scheduler
    return "stealing" in dask_scheduler.extensions


def test_the_local_cluster_runs_quiet() -> None:
    with campaign_client(None, 1) as client:
        settings = list(client.run(_worker_settings).values())
        stealing = client.run_on_scheduler(_scheduler_stealing)
    assert settings == [{"profile": False, "tick": "500ms", "trim": None}]
    assert stealing is False  # a campaign's tasks are independent and of one kind: nothing to steal
