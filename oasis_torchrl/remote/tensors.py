"""Tensors on the policy service's wire: raw little-endian bytes, a dtype and a shape (never a
pickle), and observations as maps of them.

Decoding checks that the bytes hold exactly the declared shape; anything else is a
``ValueError`` naming the entry.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping

import torch
from google.protobuf.internal.containers import MessageMap

from oasis_torchrl.proto import policy_pb2

if sys.byteorder != "little":  # the wire is little-endian; raw views would reorder bytes
    raise ImportError("oasis_torchrl.remote supports little-endian machines only")

_DTYPES: dict[torch.dtype, int] = {
    torch.bool: policy_pb2.DTYPE_BOOL,
    torch.uint8: policy_pb2.DTYPE_UINT8,
    torch.int8: policy_pb2.DTYPE_INT8,
    torch.int16: policy_pb2.DTYPE_INT16,
    torch.int32: policy_pb2.DTYPE_INT32,
    torch.int64: policy_pb2.DTYPE_INT64,
    torch.float16: policy_pb2.DTYPE_FLOAT16,
    torch.bfloat16: policy_pb2.DTYPE_BFLOAT16,
    torch.float32: policy_pb2.DTYPE_FLOAT32,
    torch.float64: policy_pb2.DTYPE_FLOAT64,
}
_TORCH_DTYPES = {value: dtype for dtype, value in _DTYPES.items()}
_NAMES = {dtype: str(dtype).removeprefix("torch.") for dtype in _DTYPES}


def dtype_name(dtype: torch.dtype) -> str:
    """The short name of a dtype, as messages and settings spell it.

    Example:
        >>> dtype_name(torch.uint8)
        'uint8'
    """
    return _NAMES.get(dtype, str(dtype))


def parse_dtype(name: str) -> torch.dtype:
    """The dtype a short name stands for.

    Example:
        >>> parse_dtype("float32")
        torch.float32
        >>> parse_dtype("float")
        Traceback (most recent call last):
        ...
        ValueError: unknown dtype 'float'; one of bool, uint8, int8, int16, int32, int64, \
float16, bfloat16, float32, float64
    """
    for dtype, short in _NAMES.items():
        if short == name:
            return dtype
    raise ValueError(f"unknown dtype {name!r}; one of {', '.join(_NAMES.values())}")


def dtype_to_proto(dtype: torch.dtype) -> int:
    """The wire value of a dtype.

    Example:
        >>> dtype_to_proto(torch.float32) == policy_pb2.DTYPE_FLOAT32
        True
    """
    if dtype not in _DTYPES:
        raise ValueError(f"dtype {dtype} cannot travel; one of {', '.join(_NAMES.values())}")
    return _DTYPES[dtype]


def dtype_from_proto(value: int) -> torch.dtype:
    """The dtype of a wire value.

    Example:
        >>> dtype_from_proto(policy_pb2.DTYPE_UINT8)
        torch.uint8
    """
    if value not in _TORCH_DTYPES:
        raise ValueError(f"unknown dtype value {value}")
    return _TORCH_DTYPES[value]


def encode(tensor: torch.Tensor) -> policy_pb2.Tensor:
    """A tensor as a wire message (one copy of its bytes, from the CPU).

    Example:
        >>> encode(torch.ones(2, 3)).shape
        [2, 3]
    """
    flat = tensor.detach().to("cpu").contiguous().reshape(-1)
    return policy_pb2.Tensor(
        dtype=dtype_to_proto(flat.dtype),
        shape=list(tensor.shape),
        data=flat.view(torch.uint8).numpy().tobytes(),
    )


def decode(message: policy_pb2.Tensor, name: str = "tensor") -> torch.Tensor:
    """The tensor a wire message holds; ``name`` is how errors call it.

    Example:
        >>> decode(encode(torch.arange(6).reshape(2, 3)))
        tensor([[0, 1, 2],
                [3, 4, 5]])
        >>> decode(policy_pb2.Tensor(dtype=policy_pb2.DTYPE_FLOAT32, shape=[2], data=b"abc"),
        ...        "state")
        Traceback (most recent call last):
        ...
        ValueError: state: 3 bytes do not hold a float32 tensor of shape [2] (8 bytes)
    """
    try:
        dtype = dtype_from_proto(message.dtype)
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None
    shape = list(message.shape)
    expected = math.prod(shape) * dtype.itemsize
    if len(message.data) != expected:
        raise ValueError(
            f"{name}: {len(message.data)} bytes do not hold a {dtype_name(dtype)} tensor of "
            f"shape {shape} ({expected} bytes)"
        )
    if not expected:
        return torch.empty(shape, dtype=dtype)
    # A writable copy: the message's bytes are immutable and the tensor may be written to.
    raw = torch.frombuffer(bytearray(message.data), dtype=torch.uint8)
    return raw.view(dtype).reshape(shape)


def encode_map(
    tensors: Mapping[str, torch.Tensor], into: MessageMap[str, policy_pb2.Tensor]
) -> None:
    """Write named tensors into a message's ``map<string, Tensor>`` field.

    Example:
        >>> request = policy_pb2.PredictChunkRequest()
        >>> encode_map({"state": torch.zeros(1, 2)}, request.observation)
        >>> list(request.observation)
        ['state']
    """
    for name, tensor in tensors.items():
        into[name].CopyFrom(encode(tensor))


def decode_map(messages: Mapping[str, policy_pb2.Tensor]) -> dict[str, torch.Tensor]:
    """The named tensors of a ``map<string, Tensor>`` field.

    Example:
        >>> request = policy_pb2.PredictChunkRequest()
        >>> encode_map({"state": torch.zeros(1, 2)}, request.observation)
        >>> decode_map(request.observation)["state"].shape
        torch.Size([1, 2])
    """
    return {name: decode(message, name) for name, message in messages.items()}
