"""Shared helpers of the client tests (server fixtures come from tests/conftest.py)."""

from __future__ import annotations

import numpy as np

from oasis_torchrl.client import A2VClient, FrameFormat, RetryPolicy
from oasis_torchrl.sim.launcher import LocalServer

PROMPT = "a sunny two-lane road"
FAST_RETRY = RetryPolicy(max_attempts=12, base_delay=0.002, max_delay=0.02)


def action_chunks(steps: int, rows: int, seed: int = 0) -> np.ndarray:
    """Reproducible float32 action chunks ``[steps, rows, 4, 2]`` in [-1, 1]."""
    rng = np.random.default_rng(seed)
    chunks = rng.uniform(-1.0, 1.0, size=(steps, rows, 4, 2)).astype(np.float32)
    chunks[..., 0] = np.abs(chunks[..., 0])  # mostly drive forward so the view changes
    return chunks


def sync_rollout(
    server: LocalServer, seed: int, chunks: np.ndarray, **client_kwargs: object
) -> list[dict[str, np.ndarray]]:
    """Frames of prompt(seed) + one Infer per chunk, by the sync client: stream -> [4, H, W, 3].

    Frames travel raw unless ``accepted_formats`` says otherwise: what a pool negotiates on
    this machine, so the two compare frame for frame.
    """
    client_kwargs = {"accepted_formats": (FrameFormat.RAW_RGB24,), **client_kwargs}
    with A2VClient(server.endpoint, api_key=server.api_key, **client_kwargs) as client:
        client.prompt(PROMPT, seed=seed)
        return [
            {name: np.stack(frames) for name, frames in client.infer(chunk).frames.items()}
            for chunk in chunks
        ]
