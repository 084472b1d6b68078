"""A user script written purely against the official ``decart_oasis`` API.

It exercises the lifecycle, the context manager, error handling, local validation and a frame
consumer, and prints a JSON summary (shapes, sequence numbers, error codes, frame checksums).
Run it once per SDK; the only difference between runs is which module the API is imported from:

    DECART_API_KEY=... python official_api_script.py --sdk decart_oasis --endpoint http://h:p
    DECART_API_KEY=... python official_api_script.py --sdk oasis_torchrl.client --endpoint ...

Both SDKs must print the same summary against the same server.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

PROMPT = "a sunny two-lane road through fields"
ACTIONS = [
    [[0.6, 0.0], [0.6, 0.1], [0.7, 0.2], [0.7, 0.0]],
    [[1.0, -0.3], [0.8, -0.3], [0.5, 0.0], [0.2, 0.4]],
    [[-0.5, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.3, -1.0]],
]


class RecordingConsumer:
    """A frame consumer (official ``FrameConsumer`` protocol) that records what it receives."""

    def __init__(self) -> None:
        self.events: list[Any] = []

    def submit(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        self.events.append({name: len(chunk) for name, chunk in sorted(frames.items())})

    def new_clip(self) -> None:
        self.events.append("new_clip")


def error_summary(action: Callable[[], Any], sdk: Any) -> dict[str, Any]:
    """Run ``action`` and describe the exception it raised (or that it raised none)."""
    try:
        action()
    except sdk.A2VError as error:
        return {
            "kind": "A2VError",
            "code": int(error.code),
            "message_is_str": isinstance(error.message, str),
            "details_is_dict": isinstance(error.details, dict),
            "is_base": isinstance(error, sdk.DecartRoboticsError),
        }
    except sdk.DecartRoboticsError:
        return {"kind": "DecartRoboticsError"}
    except ValueError:
        return {"kind": "ValueError"}
    return {"kind": None}


def chunk_summary(result: Any, streams: Sequence[Any]) -> dict[str, Any]:
    """Sequence number, shapes and checksums of one A2VResult."""
    return {
        "sequence_num": result.sequence_num,
        "streams_match": tuple(result.streams) == tuple(streams),
        "frames": {
            name: {
                "count": len(frames),
                "shapes": sorted({tuple(f.shape) for f in frames}),
                "dtypes": sorted({str(f.dtype) for f in frames}),
                "sha256": [
                    hashlib.sha256(np.ascontiguousarray(f).tobytes()).hexdigest() for f in frames
                ],
            }
            for name, frames in sorted(result.frames.items())
        },
    }


def run(sdk: Any, endpoint: str, api_key: str) -> dict[str, Any]:
    """Drive the SDK through a typical session and collect observable behaviour."""
    summary: dict[str, Any] = {"default_endpoint": sdk.DEFAULT_ENDPOINT}

    no_key = sdk.A2VClient(endpoint, api_key="")
    summary["missing_key"] = error_summary(no_key.initialize, sdk)
    summary["before_initialize"] = error_summary(lambda: no_key.prompt(PROMPT), sdk)
    no_key.close()

    wrong_key = sdk.A2VClient(endpoint, api_key="not-a-valid-key")
    summary["wrong_key"] = error_summary(wrong_key.initialize, sdk)
    wrong_key.close()

    rear = sdk.A2VClient(endpoint, api_key=api_key, required_streams=("rear",))
    summary["missing_stream"] = error_summary(rear.initialize, sdk)
    rear.close()

    consumer = RecordingConsumer()
    with sdk.A2VClient(endpoint, api_key=api_key, frame_consumer=consumer) as client:
        summary["session"] = {
            "has_id": bool(client.session_id),
            "has_target": isinstance(client.session_target, str),
            "streams": [[s.name, s.sensor_type, s.height, s.width] for s in client.streams],
        }
        zeros = [[0.0, 0.0]] * 4
        summary["infer_before_prompt"] = error_summary(lambda: client.infer(zeros), sdk)
        summary["validation"] = [
            error_summary(lambda bad=bad: client.infer(bad), sdk)
            for bad in ([[0.0, 0.0]] * 3, [[float("nan"), 0.0]] * 4, [[0.0, 1.5]] * 4)
        ]
        client.prompt(PROMPT)
        summary["first_clip"] = [
            chunk_summary(client.infer(actions), client.streams) for actions in ACTIONS
        ]
        client.prompt(PROMPT)
        summary["second_clip"] = [
            chunk_summary(client.infer(np.asarray(ACTIONS[0], np.float32)), client.streams)
        ]
    summary["after_close"] = {
        "session_id": client.session_id,
        "infer": error_summary(lambda: client.infer(zeros), sdk),
    }
    summary["consumer_events"] = consumer.events

    try:
        with sdk.A2VClient(endpoint, api_key=api_key) as client:
            raise KeyError("raised inside the with block")
    except KeyError as error:
        summary["with_block_error"] = str(error)

    os.environ["DECART_ROBOTICS_ENDPOINT"] = endpoint
    explicit = sdk.A2VClient.from_env(api_key=api_key)
    summary["from_env_endpoint_matches"] = explicit.endpoint == endpoint
    streams = explicit.initialize()
    summary["initialize_returns_streams"] = tuple(streams) == tuple(explicit.streams)
    explicit.prompt(PROMPT)
    summary["explicit_sequence"] = [explicit.infer(a).sequence_num for a in ACTIONS[:2]]
    explicit.close()
    explicit.close()
    summary["closed_twice"] = explicit.session_id is None
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sdk", default="decart_oasis", help="module to import the API from")
    parser.add_argument("--endpoint", required=True)
    args = parser.parse_args()
    sdk = importlib.import_module(args.sdk)  # the only line that differs between the two runs
    summary = run(sdk, args.endpoint, os.environ["DECART_API_KEY"])
    print(json.dumps(summary, sort_keys=True))


if __name__ == "__main__":
    main()
