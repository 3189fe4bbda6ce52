"""Closing the farm's local Dask cluster (csm_engine/farm/command.py ``close``), without
Blender: the workers are plain Dask worker processes.

Dask logs a traceback on the terminal when a worker's heartbeat is in flight as the
scheduler shuts down, although nothing failed. Here the scheduler answers heartbeats a
second late, so every heartbeat is in flight when the cluster closes: a plain close
prints the traceback (the control), the farm's close does not.
"""
import asyncio
import time

import distributed

from csm_engine.farm import command


def cluster_with_heartbeats_in_flight():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       memory_limit=0, dashboard_address=None,
                                       scheduler_port=0)
    client = distributed.Client(cluster)
    answer = cluster.scheduler.handlers["heartbeat_worker"]

    async def late_answer(*args, **kwargs):
        await asyncio.sleep(1.0)
        return answer(*args, **kwargs)

    cluster.scheduler.handlers["heartbeat_worker"] = late_answer
    time.sleep(1.5)
    return client, cluster


def test_a_plain_close_prints_the_heartbeat_traceback(capfd):
    client, cluster = cluster_with_heartbeats_in_flight()
    client.close()
    cluster.close()
    assert command.worker.HEARTBEAT_FAILURE in capfd.readouterr().err


def test_the_farm_closes_its_cluster_without_a_traceback(capfd):
    client, cluster = cluster_with_heartbeats_in_flight()
    command.close(client, cluster)
    err = capfd.readouterr().err
    assert "Traceback" not in err, err
    assert cluster.status.name == "closed"
