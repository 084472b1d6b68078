"""One local Ray runtime for the tests of this package that use it (Ray takes seconds to
start); the cluster tests run their drivers inside network namespaces instead."""

from __future__ import annotations

import logging
from collections.abc import Iterator

import pytest

ray = pytest.importorskip("ray")

START_ATTEMPTS = 3
"""Starts of the local runtime before the tests error (see :func:`ray_runtime`)."""


@pytest.fixture(scope="package")
def ray_runtime() -> Iterator[None]:
    """A local Ray runtime (2 CPUs, small object store, no dashboard) for the package."""
    settings = {
        "address": "local",
        "num_cpus": 2,
        "include_dashboard": False,
        "object_store_memory": 200 * 1024**2,
        "logging_level": logging.WARNING,
    }
    for attempt in range(1, START_ATTEMPTS + 1):
        try:
            ray.init(**settings)
            break
        except Exception:
            # Ray's start-up has deadlines a loaded 2-core machine can miss: a RuntimeError
            # ("Timed out waiting for file .../gcs_server_port_...") or a bare Exception ("The
            # current node timed out during startup"); a later start succeeds.
            ray.shutdown()
            if attempt == START_ATTEMPTS:
                raise
    yield
    ray.shutdown()
