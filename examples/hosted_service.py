"""Drive Decart's hosted Oasis model: the same env and client as on the local simulator, with
your API key.

    DECART_API_KEY=... python examples/hosted_service.py

``DECART_ROBOTICS_ENDPOINT`` points it at another A2V server (as the official SDK's
``from_env`` does), e.g. ``oasis-torchrl serve`` on your machine.
"""

from __future__ import annotations

import os
import sys

import torch

from oasis_torchrl.client import A2VClient
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.protocol import API_KEY_ENV_VAR, DEFAULT_ENDPOINT, ENDPOINT_ENV_VAR

SMOKE = os.environ.get("OASIS_EXAMPLE_SMOKE") == "1"
STEPS = 2 if SMOKE else 20
FRAME_SIZE = (128, 192)  # (height, width) the frames are decoded to; the model sends 768x512


def main() -> int:
    api_key = os.environ.get(API_KEY_ENV_VAR)
    if not api_key:
        print(
            f"{API_KEY_ENV_VAR} is not set: this example drives the hosted model and needs your "
            f"Decart API key (export {API_KEY_ENV_VAR}=...). The other examples run offline on "
            "the embedded simulator.",
            file=sys.stderr,
        )
        return 1
    endpoint = os.environ.get(ENDPOINT_ENV_VAR) or DEFAULT_ENDPOINT

    # One session, the official SDK's way (A2VClient is a drop-in for decart_oasis.A2VClient).
    with A2VClient(endpoint, api_key=api_key, resize=FRAME_SIZE) as client:
        client.prompt("a rainy highway at dusk")
        result = client.infer([[0.5, 0.0]] * 4)
        print("one chunk:", {name: frames[-1].shape for name, frames in result.frames.items()})

    # Several sessions as one batched TorchRL env: every step sends their Infer calls at once.
    env = OasisEnv(
        endpoint,
        num_envs=2,
        prompts=["urban street", "rural road"],
        api_key=api_key,
        frame_size=FRAME_SIZE,
        max_steps=STEPS,
    )
    try:
        env.set_seed(0)
        td = env.reset()
        for _ in range(STEPS):
            action = torch.tensor([[0.6, 0.0]]).expand(2, 4, 2)
            td = env.step(td.set("action", action))["next"]
        print("batched env:", td["pixels", "front"].shape)
    finally:
        env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
