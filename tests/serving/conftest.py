"""Fixtures of the policy-server tests: a policy folder of ours, servers on loopback, clients.

- ``policy_folder``: a LeRobot policy folder exported from a driving network whose actions
  depend visibly on its inputs (64x96 images, 2 frames).
- ``server_factory(load=None, **settings)``: a started :class:`PolicyServer` (the keys below;
  ``load`` defaults to serving ``policy_folder``), stopped after the test.
- ``policy_server``: one such server over ``policy_folder``, ready.
- ``stub_factory(server)``: raw ``PolicyService`` stubs on a plain-text channel.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import grpc
import pytest
import torch

from oasis_torchrl.config.policy_serving import PolicyServerConfig
from oasis_torchrl.drivers.folders import export_lerobot
from oasis_torchrl.models import DrivingNet
from oasis_torchrl.proto import policy_pb2_grpc
from oasis_torchrl.serving.host import Loader
from oasis_torchrl.serving.served import load_served_policy
from oasis_torchrl.serving.server import PolicyServer

KEYS = ("policy-key-alpha", "policy-key-beta")


def sensitive_net(seed: int = 0) -> DrivingNet:
    """A driving network whose chunk moves with its inputs (a fresh one's last actor layer is
    scaled down to start near one action; here it is not)."""
    torch.manual_seed(seed)
    net = DrivingNet()
    torch.nn.init.normal_(net.actor[-1].weight, std=1.0)
    return net


@pytest.fixture(scope="session")
def policy_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A LeRobot ``oasis`` policy folder (``export_lerobot``)."""
    return export_lerobot(sensitive_net(), tmp_path_factory.mktemp("served") / "policy")


@pytest.fixture
def server_factory(policy_folder: Path) -> Iterator[Callable[..., PolicyServer]]:
    """Start policy servers; all are stopped after the test."""
    servers: list[PolicyServer] = []

    def start(load: Loader | None = None, **settings: Any) -> PolicyServer:
        config = PolicyServerConfig(**{"api_keys": KEYS, **settings})
        server = PolicyServer(config, load or (lambda: load_served_policy(str(policy_folder))))
        server.start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop(grace=0)


@pytest.fixture
def policy_server(server_factory: Callable[..., PolicyServer]) -> PolicyServer:
    """A ready server of ``policy_folder``."""
    server = server_factory()
    assert server.wait_until_loaded(120)
    return server


@pytest.fixture
def stub_factory() -> Iterator[Callable[[PolicyServer], policy_pb2_grpc.PolicyServiceStub]]:
    """Raw stubs to a server (plain text); channels closed after the test."""
    channels: list[grpc.Channel] = []

    def connect(server: PolicyServer) -> policy_pb2_grpc.PolicyServiceStub:
        channel = grpc.insecure_channel(server.endpoint.removeprefix("grpc://"))
        channels.append(channel)
        return policy_pb2_grpc.PolicyServiceStub(channel)

    yield connect
    for channel in channels:
        channel.close()
