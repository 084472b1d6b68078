"""One local Ray runtime for all tests of this package (Ray takes seconds to start)."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

ray = pytest.importorskip("ray")


@pytest.fixture(scope="package", autouse=True)
def ray_runtime() -> Iterator[None]:
    """A local Ray runtime (2 CPUs, small object store, no dashboard) for the package."""
    settings = {
        "address": "local",
        "num_cpus": 2,
        "include_dashboard": False,
        "object_store_memory": 200 * 1024**2,
        "logging_level": logging.WARNING,
    }
    try:
        ray.init(**settings)
    except RuntimeError:
        # Ray's GCS server can miss its start-up deadline on a loaded 2-core machine ("Timed
        # out waiting for file .../gcs_server_port_..."); a second start succeeds.
        ray.shutdown()
        ray.init(**settings)
    yield
    ray.shutdown()
