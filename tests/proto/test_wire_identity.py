"""Our A2V protos are wire-identical to the official ``decart-oasis==0.0.2`` SDK.

The official generated modules register the same symbols in protobuf's default descriptor pool,
so they are described in a subprocess and compared here as plain data.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

DESCRIBE = r"""
import importlib, json, sys
from google.protobuf import descriptor_pb2

def field(f):
    return {"number": f.number, "type": f.type, "type_name": f.type_name, "label": f.label,
            "proto3_optional": f.proto3_optional,
            "oneof": f.oneof_index if f.HasField("oneof_index") else None}

def message(m):
    return {"fields": {f.name: field(f) for f in m.field},
            "nested": {n.name: message(n) for n in m.nested_type},
            "map_entry": m.options.map_entry,
            "oneofs": [o.name for o in m.oneof_decl]}

out = {}
for module in sys.argv[1:]:
    fdp = descriptor_pb2.FileDescriptorProto()
    importlib.import_module(module).DESCRIPTOR.CopyToProto(fdp)
    out[fdp.package] = {
        "syntax": fdp.syntax,
        "messages": {m.name: message(m) for m in fdp.message_type},
        "enums": {e.name: {v.name: v.number for v in e.value} for e in fdp.enum_type},
        "services": {
            s.name: {m.name: [m.input_type, m.output_type, m.client_streaming, m.server_streaming]
                     for m in s.method}
            for s in fdp.service
        },
    }
print(json.dumps(out, sort_keys=True))
"""


def describe(package: str) -> dict:
    modules = [f"{package}.common_pb2", f"{package}.a2v_pb2"]
    result = subprocess.run(
        [sys.executable, "-c", DESCRIBE, *modules], capture_output=True, text=True, check=True
    )
    return json.loads(result.stdout)


@pytest.fixture(scope="module")
def official() -> dict:
    pytest.importorskip("decart_oasis", reason="decart-oasis==0.0.2 is a test dependency")
    return describe("decart_oasis._proto")


@pytest.fixture(scope="module")
def ours() -> dict:
    return describe("oasis_torchrl.proto")


def test_same_packages(official: dict, ours: dict) -> None:
    assert set(ours) == set(official) == {"decart.inference.a2v", "decart.inference.common"}


@pytest.mark.parametrize("package", ["decart.inference.a2v", "decart.inference.common"])
def test_same_messages_enums_and_services(official: dict, ours: dict, package: str) -> None:
    assert ours[package]["syntax"] == official[package]["syntax"] == "proto3"
    assert ours[package]["messages"] == official[package]["messages"]
    assert ours[package]["enums"] == official[package]["enums"]
    assert ours[package]["services"] == official[package]["services"]


def test_service_methods_are_unary(ours: dict) -> None:
    methods = ours["decart.inference.a2v"]["services"]["A2VService"]
    assert sorted(methods) == ["Finish", "Infer", "Initialize", "Prompt"]
    assert all(not client and not server for _, _, client, server in methods.values())


def test_local_services_stay_out_of_decart_namespace() -> None:
    from oasis_torchrl.proto import sim_pb2

    assert sim_pb2.DESCRIPTOR.package == "oasis_torchrl.sim.v1"
