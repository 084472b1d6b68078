"""The A2V protocol's generated messages and stubs, and the ``.proto`` sources they come from.

``a2v_pb2`` / ``common_pb2`` are wire-identical to Decart's ``decart.inference`` packages;
``sim_pb2`` is the embedded simulator's own ``oasis_torchrl.sim.v1``. The sources ship with the
package (``make protos`` regenerates the modules from them), e.g. for clients in other languages:

>>> sources = proto_sources()
>>> sorted(sources)[0], "service A2VService" in sources["oasis_torchrl/proto/a2v.proto"]
('oasis_torchrl/proto/a2v.proto', True)
"""

from __future__ import annotations

from importlib.resources import files


def proto_sources() -> dict[str, str]:
    """Each shipped ``.proto`` source by its import path (what ``protoc -I`` resolves).

    Found through :mod:`importlib.resources`, so it works from a source tree, a wheel or a zip.
    """
    package = files(__package__)
    return {
        f"{__package__.replace('.', '/')}/{entry.name}": entry.read_text(encoding="utf-8")
        for entry in package.iterdir()
        if entry.name.endswith(".proto")
    }
