"""Drive a server with the OFFICIAL ``decart_oasis`` client and print what happened as JSON.

Runs in its own interpreter: the official SDK's generated protos register the same symbols as
oasis-torchrl's, so the two must not share a process. Never imports ``oasis_torchrl``.

Usage: ``DECART_API_KEY=... python official_lifecycle.py http://127.0.0.1:PORT``
"""

from __future__ import annotations

import json
import sys

import numpy as np
from decart_oasis import A2VClient, A2VError


def front_after(client: A2VClient, prompt: str, steering: float, chunks: int) -> np.ndarray:
    """Prompt, drive ``chunks`` Infers at constant steering, return the last front frame."""
    client.prompt(prompt)
    result = None
    for _ in range(chunks):
        result = client.infer([[0.8, steering]] * 4)
    assert result is not None
    return result.frames["front"][-1]


def main(endpoint: str) -> dict[str, object]:
    """The lifecycle report: streams, frame shapes, steering effect, bad-key error code."""
    report: dict[str, object] = {}
    with A2VClient(endpoint, tls=False) as client:
        report["streams"] = [[s.name, s.width, s.height] for s in client.streams]
        report["session_target"] = client.session_target is not None
        client.prompt("a sunny two-lane highway")
        shapes, sequence_nums = set(), []
        for _ in range(6):
            result = client.infer([[0.6, 0.0]] * 4)
            sequence_nums.append(result.sequence_num)
            shapes |= {
                (name, len(frames), *frames[-1].shape) for name, frames in result.frames.items()
            }
        report["shapes"] = sorted(shapes)
        report["sequence_nums"] = sequence_nums
        left = front_after(client, "a snowy mountain pass", -1.0, 4)
        right = front_after(client, "a snowy mountain pass", 1.0, 4)
        report["steering_difference"] = float(np.abs(left.astype(int) - right.astype(int)).mean())
    try:
        A2VClient(endpoint, api_key="definitely-not-a-key", tls=False).initialize()
        report["bad_key_code"] = None
    except A2VError as error:
        report["bad_key_code"] = error.code
    return report


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1])))
