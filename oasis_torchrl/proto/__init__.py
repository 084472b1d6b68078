"""The A2V protocol's generated messages and stubs, and the ``.proto`` sources they come from.

``a2v_pb2`` / ``common_pb2`` are wire-identical to Decart's ``decart.inference`` packages;
``sim_pb2`` is the embedded simulator's own ``oasis_torchrl.sim.v1``. The sources are the
repository's top-level ``protos/`` folder, imported as ``oasis_torchrl/proto/<name>.proto``
(``make protos`` regenerates the modules from them); a wheel carries them inside this package
(:mod:`oasis_torchrl.shipped`), e.g. for clients in other languages:

>>> sources = proto_sources()
>>> sorted(sources)[0], "service A2VService" in sources["oasis_torchrl/proto/a2v.proto"]
('oasis_torchrl/proto/a2v.proto', True)
"""

from __future__ import annotations

IMPORT_PREFIX = __package__.replace(".", "/")
"""The folder the sources are imported from (``protoc -Ioasis_torchrl/proto=protos``)."""


def proto_sources() -> dict[str, str]:
    """Each ``.proto`` source by its import path (what ``protoc -I`` resolves)."""
    # Imported here: the embedded server imports this package and nothing above the protocol.
    from oasis_torchrl.shipped import shipped_files

    return {
        f"{IMPORT_PREFIX}/{path.name}": path.read_text(encoding="utf-8")
        for path in shipped_files("proto", "protos", "*.proto")
    }
