"""What a served policy reads and writes: :class:`Feature` (name, per-row shape, dtype,
bounds), checks of an observation against them, and sample observations.

A feature's name is its TensorDict key, nested keys joined by ``"."``: the env's
``("pixels", "front")`` is ``"pixels.front"``. An observation holds every input feature,
shaped ``[rows, *feature.shape]``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Composite, TensorSpec

from oasis_torchrl.proto import policy_pb2
from oasis_torchrl.remote.tensors import dtype_from_proto, dtype_name, dtype_to_proto, parse_dtype

NestedKey = str | tuple[str, ...]
SAMPLE_RANGE = (-1.0, 1.0)
"""Where sample values of an unbounded float feature are drawn."""


def name_to_key(name: str) -> NestedKey:
    """The TensorDict key a feature name stands for.

    Example:
        >>> name_to_key("pixels.front"), name_to_key("state")
        (('pixels', 'front'), 'state')
    """
    parts = tuple(name.split("."))
    return parts if len(parts) > 1 else parts[0]


def key_to_name(key: NestedKey) -> str:
    """The feature name of a TensorDict key.

    Example:
        >>> key_to_name(("pixels", "front"))
        'pixels.front'
    """
    return ".".join(key) if isinstance(key, tuple) else key


class InvalidObservation(ValueError):
    """An observation that does not match the policy's input features, naming what is wrong.

    Example:
        >>> str(InvalidObservation("state", "must be float32, got float64"))
        "feature 'state' must be float32, got float64"
    """

    def __init__(self, feature: str, problem: str) -> None:
        super().__init__(f"feature {feature!r} {problem}")
        self.feature = feature


@dataclass(frozen=True)
class Feature:
    """One input or output of a policy, for one row.

    Args:
        name: the TensorDict key, nested keys joined by ``"."``.
        shape: the shape of one row's value.
        dtype: its element type.
        low: lower bound of every element, if declared.
        high: upper bound of every element, if declared.
        names: names of the last dimension's entries, if any.

    Example:
        >>> feature = Feature.parse("pixels.front:uint8:2x64x96x3")
        >>> feature.key, feature.shape, feature.describe()
        (('pixels', 'front'), (2, 64, 96, 3), 'pixels.front: uint8 [2, 64, 96, 3]')
        >>> Feature.from_proto(feature.to_proto()) == feature
        True
    """

    name: str
    shape: tuple[int, ...]
    dtype: torch.dtype
    low: float | None = None
    high: float | None = None
    names: tuple[str, ...] = ()

    @property
    def key(self) -> NestedKey:
        """The TensorDict key of the feature."""
        return name_to_key(self.name)

    def describe(self) -> str:
        """``name: dtype [shape]``, as messages show it."""
        return f"{self.name}: {dtype_name(self.dtype)} {list(self.shape)}"

    @classmethod
    def parse(cls, text: str) -> Feature:
        """A feature from ``NAME:DTYPE:SHAPE`` (shape ``2x64x96x3``; ``scalar`` for ``()``).

        Example:
            >>> Feature.parse("state:float32:2").shape
            (2,)
            >>> Feature.parse("state:float32")
            Traceback (most recent call last):
            ...
            ValueError: feature 'state:float32' must look like NAME:DTYPE:SHAPE, \
e.g. pixels.front:uint8:2x64x96x3 or state:float32:2
        """
        parts = text.strip().split(":")
        try:
            name, dtype, shape = parts
            dims = () if shape == "scalar" else tuple(int(dim) for dim in shape.split("x"))
            if not name or any(dim < 1 for dim in dims):
                raise ValueError
        except ValueError:
            raise ValueError(
                f"feature {text!r} must look like NAME:DTYPE:SHAPE, e.g. "
                "pixels.front:uint8:2x64x96x3 or state:float32:2"
            ) from None
        return cls(name, dims, parse_dtype(dtype))

    def to_proto(self) -> policy_pb2.Feature:
        """The feature as a wire message."""
        message = policy_pb2.Feature(
            name=self.name,
            dtype=dtype_to_proto(self.dtype),
            shape=list(self.shape),
            names=list(self.names),
        )
        if self.low is not None:
            message.low = self.low
        if self.high is not None:
            message.high = self.high
        return message

    @classmethod
    def from_proto(cls, message: policy_pb2.Feature) -> Feature:
        """The feature a wire message describes."""
        return cls(
            name=message.name,
            shape=tuple(message.shape),
            dtype=dtype_from_proto(message.dtype),
            low=message.low if message.HasField("low") else None,
            high=message.high if message.HasField("high") else None,
            names=tuple(message.names),
        )

    def check(self, value: torch.Tensor, rows: int) -> None:
        """Raise :class:`InvalidObservation` unless ``value`` is ``rows`` finite rows of this
        feature."""
        if value.dtype != self.dtype:
            raise InvalidObservation(
                self.name, f"must be {dtype_name(self.dtype)}, got {dtype_name(value.dtype)}"
            )
        wanted = [rows, *self.shape]
        if list(value.shape) != wanted:
            raise InvalidObservation(
                self.name,
                f"must be [rows, {', '.join(map(str, self.shape))}] = {wanted}, "
                f"got {list(value.shape)}",
            )
        if value.is_floating_point():
            bad = ~torch.isfinite(value)
            if bad.any():
                index = [int(i) for i in bad.nonzero()[0]]
                raise InvalidObservation(
                    self.name, f"holds {value[tuple(index)].item()} at {index} (row {index[0]})"
                )

    def sample(self, rows: int, generator: torch.Generator) -> torch.Tensor:
        """``rows`` random values within the bounds (floats: ``SAMPLE_RANGE`` if unbounded)."""
        shape = (rows, *self.shape)
        if self.dtype == torch.bool:
            return torch.randint(0, 2, shape, generator=generator).bool()
        if self.dtype.is_floating_point:
            low = SAMPLE_RANGE[0] if self.low is None else self.low
            high = SAMPLE_RANGE[1] if self.high is None else self.high
            values = torch.rand(shape, generator=generator, dtype=torch.float64)
            return (low + (high - low) * values).to(self.dtype)
        info = torch.iinfo(self.dtype)
        low = max(info.min, math.ceil(self.low)) if self.low is not None else max(info.min, -128)
        high = min(info.max, math.floor(self.high)) if self.high is not None else min(info.max, 127)
        return torch.randint(low, high + 1, shape, generator=generator, dtype=self.dtype)


def features_of_spec(spec: Composite) -> list[Feature]:
    """The leaves of a TorchRL spec of one row, as features (bounds of uniform ``Bounded``
    leaves kept).

    Example:
        >>> from torchrl.data import Unbounded
        >>> spec = Composite(pixels=Composite(front=Bounded(0, 255, (64, 96, 3),
        ...     dtype=torch.uint8)), state=Unbounded((2,)))
        >>> [feature.describe() for feature in features_of_spec(spec)]
        ['pixels.front: uint8 [64, 96, 3]', 'state: float32 [2]']
    """
    features = []
    for key in spec.keys(include_nested=True, leaves_only=True):
        leaf: TensorSpec = spec[key]
        low, high = _uniform_bounds(leaf)
        features.append(Feature(key_to_name(key), tuple(leaf.shape), leaf.dtype, low, high))
    return features


def _uniform_bounds(spec: TensorSpec) -> tuple[float | None, float | None]:
    if not isinstance(spec, Bounded):
        return None, None
    low, high = spec.space.low, spec.space.high
    if (low == low.flatten()[0]).all() and (high == high.flatten()[0]).all():
        return float(low.flatten()[0]), float(high.flatten()[0])
    return None, None


def check_observation(
    observation: Mapping[str, torch.Tensor], features: Sequence[Feature], max_rows: int
) -> int:
    """The number of rows of ``observation``, after checking it holds exactly ``features``
    (dtype, shape, finite values) with the same number of rows, at most ``max_rows``.

    Example:
        >>> features = [Feature("state", (2,), torch.float32)]
        >>> check_observation({"state": torch.zeros(3, 2)}, features, max_rows=8)
        3
        >>> check_observation({"state": torch.tensor([[0.0, float("nan")]])}, features, 8)
        Traceback (most recent call last):
        ...
        oasis_torchrl.remote.features.InvalidObservation: feature 'state' holds nan at \
[0, 1] (row 0)
    """
    names = {feature.name for feature in features}
    unknown = sorted(set(observation) - names)
    if unknown:
        expected = ", ".join(sorted(names))
        raise InvalidObservation(unknown[0], f"is not an input of this policy (inputs: {expected})")
    missing = [feature.name for feature in features if feature.name not in observation]
    if missing:
        raise InvalidObservation(missing[0], "is missing from the observation")
    rows = _rows(observation, features)
    if not 1 <= rows <= max_rows:
        raise InvalidObservation(
            features[0].name, f"has {rows} rows; a request holds 1 to {max_rows}"
        )
    for feature in features:
        feature.check(observation[feature.name], rows)
    return rows


def _rows(observation: Mapping[str, torch.Tensor], features: Sequence[Feature]) -> int:
    first = features[0]
    value = observation[first.name]
    rows = value.shape[0] if value.dim() else 0
    for feature in features[1:]:
        other = observation[feature.name]
        if not other.dim() or other.shape[0] != rows:
            raise InvalidObservation(
                feature.name,
                f"has {other.shape[0] if other.dim() else 0} rows, {first.name!r} has {rows}",
            )
    return rows


def sample_observation(features: Iterable[Feature], rows: int, seed: int = 0) -> dict:
    """A valid observation of ``rows`` rows: random values within each feature's bounds.

    Example:
        >>> features = [Feature("pixels.front", (8, 8, 3), torch.uint8, 0, 255)]
        >>> sample_observation(features, rows=2)["pixels.front"].shape
        torch.Size([2, 8, 8, 3])
    """
    generator = torch.Generator().manual_seed(seed)
    return {feature.name: feature.sample(rows, generator) for feature in features}


def neutral_observation(features: Iterable[Feature], rows: int) -> dict:
    """An observation of ``rows`` rows of zeros, moved into each feature's bounds: a plain
    input to probe a policy with (its warm-up).

    Example:
        >>> neutral_observation([Feature("speed", (1,), torch.float32, 2.0, 5.0)], 1)["speed"]
        tensor([[2.]])
    """
    neutral = {}
    for feature in features:
        value = max(0.0, -math.inf if feature.low is None else feature.low)
        value = min(value, math.inf if feature.high is None else feature.high)
        neutral[feature.name] = torch.full((rows, *feature.shape), value, dtype=feature.dtype)
    return neutral


def as_tensordict(observation: Mapping[str, torch.Tensor], rows: int) -> TensorDictBase:
    """A flat observation as a TensorDict of ``rows`` rows, names turned into nested keys.

    Example:
        >>> td = as_tensordict({"pixels.front": torch.zeros(2, 3), "state": torch.zeros(2)}, 2)
        >>> td["pixels", "front"].shape
        torch.Size([2, 3])
    """
    td = TensorDict(batch_size=[rows])
    for name, value in observation.items():
        td.set(name_to_key(name), value)
    return td
