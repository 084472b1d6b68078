"""The world model through LeRobot's own tools: record a drive with the oasis robot into a
LeRobot dataset, train policies on it with ``lerobot-train`` (a stock ``act`` and the project's
``oasis``), and evaluate them in the oasis env with LeRobot's own evaluation loop.

    python examples/lerobot_world_model.py --root outputs/example_drive --train act oasis
    python examples/lerobot_world_model.py --root outputs/example_drive2 \\
        --policy outputs/act/checkpoints/last/pretrained_model

The robot is what ``lerobot-record --robot.type=oasis`` drives; here a scripted driver weaves
along the road instead of a person at the keyboard. Each recorded row holds the newest camera
frames, the previous action as ``observation.state`` and the action applied next, the features
of the project's own datasets. Training is ``lerobot-train`` itself, run as a command; ACT
starts from scratch (``--policy.pretrained_backbone_weights=null``: no download). The evaluation
is ``lerobot-eval --env.type=oasis`` in a few lines.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.video import RGBEncoderConfig
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.envs.factory import make_env, make_env_pre_post_processors
from lerobot.policies.factory import make_policy, make_pre_post_processors
from lerobot.robots.utils import make_robot_from_config
from lerobot.scripts.lerobot_eval import eval_policy_all
from lerobot.utils.constants import ACTION, OBS_STR
from lerobot.utils.feature_utils import build_dataset_frame, hw_to_dataset_features
from lerobot.utils.import_utils import register_third_party_plugins
from lerobot_env_oasis import OasisEnvConfig
from lerobot_robot_oasis import OasisRobotConfig

PROMPT = "urban"
FPS = 20


def weave(tick: int) -> dict[str, float]:
    """Steady throttle, steering swinging gently left and right every 4 seconds."""
    return {"throttle.vel": 0.6, "steering.vel": 0.15 * math.sin(2 * math.pi * tick / (4 * FPS))}


def record(root: Path, episodes: int, seconds: float, seed: int) -> LeRobotDataset:
    """Drive ``episodes`` episodes (episode ``N`` is the world of ``seed + N``) into a dataset."""
    robot = make_robot_from_config(OasisRobotConfig(prompt=PROMPT, seed=seed))
    features = {
        **hw_to_dataset_features(robot.observation_features, OBS_STR),
        **hw_to_dataset_features(robot.action_features, ACTION),
    }
    dataset = LeRobotDataset.create(
        "local/example_drive",
        FPS,
        root=root,
        robot_type=robot.name,
        features=features,
        rgb_encoder=RGBEncoderConfig(vcodec="h264"),
        streaming_encoding=True,
    )
    robot.connect()
    try:
        for episode in range(episodes):
            robot.start_episode(episode)
            for tick in range(int(seconds * FPS)):
                observation = robot.get_observation()
                action = robot.send_action(weave(tick))
                dataset.add_frame(
                    {
                        **build_dataset_frame(features, observation, prefix=OBS_STR),
                        **build_dataset_frame(features, action, prefix=ACTION),
                        "task": PROMPT,
                    }
                )
            dataset.save_episode()
    finally:
        robot.disconnect()
        dataset.finalize()
    return dataset


TRAIN_FLAGS = {"act": ["--policy.pretrained_backbone_weights=null"], "oasis": []}
"""Extra ``lerobot-train`` flags per policy type."""


def train(dataset: Path, policy_type: str, steps: int, output: Path) -> Path:
    """``lerobot-train`` of a ``policy_type`` policy on the dataset; its last checkpoint."""
    command = [sys.executable, "-m", "lerobot.scripts.lerobot_train"]
    command += [f"--policy.type={policy_type}", *TRAIN_FLAGS[policy_type]]
    command += ["--policy.device=cpu", "--policy.push_to_hub=false"]
    command += ["--dataset.repo_id=local/example_drive", f"--dataset.root={dataset}"]
    command += [f"--steps={steps}", f"--save_freq={steps}", "--batch_size=8", "--num_workers=0"]
    subprocess.run([*command, f"--output_dir={output}"], check=True)
    return output / "checkpoints" / "last" / "pretrained_model"


def _policy_config(folder: str) -> PreTrainedConfig:
    """The saved config of a policy folder, to run on the CPU."""
    register_third_party_plugins()  # plugin policy types, e.g. the oasis policy
    config = PreTrainedConfig.from_pretrained(folder)
    config.pretrained_path = folder
    config.device = "cpu"
    return config


def evaluate(policy_folder: str, sessions: int, frames: int, seed: int) -> dict:
    """LeRobot's evaluation of a policy folder on ``sessions`` world-model sessions at once,
    episodes of ``frames`` frames."""
    env_config = OasisEnvConfig(task=PROMPT, episode_length=frames)
    envs = make_env(env_config, n_envs=sessions)
    policy_config = _policy_config(policy_folder)
    policy = make_policy(policy_config, env_cfg=env_config)
    preprocessor, postprocessor = make_pre_post_processors(
        policy_config, pretrained_path=policy_folder
    )
    env_preprocessor, env_postprocessor = make_env_pre_post_processors(env_config, policy_config)
    info = eval_policy_all(
        envs,
        policy,
        env_preprocessor,
        env_postprocessor,
        preprocessor,
        postprocessor,
        n_episodes=sessions,
        start_seed=seed,
    )
    overall = info["overall"]
    return {  # distance reward: the sum is metres driven before a collision (or the end)
        "mean_distance": overall["avg_sum_reward"],
        "collision_rate": 1 - overall["pc_success"] / 100,
        "episodes": overall["n_episodes"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, required=True, help="dataset folder to create")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each episode")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--policy", help="a LeRobot policy folder to evaluate in the world model")
    parser.add_argument(
        "--train", nargs="*", default=[], choices=sorted(TRAIN_FLAGS), help="policies to train"
    )
    parser.add_argument("--train-steps", type=int, default=2000, help="lerobot-train's --steps")
    parser.add_argument("--sessions", type=int, default=4, help="sessions evaluated at once")
    parser.add_argument("--episode-frames", type=int, default=200, help="frames per evaluation")
    args = parser.parse_args()
    dataset = record(args.root, args.episodes, args.seconds, args.seed)
    print(f"recorded {dataset.num_episodes} episodes, {dataset.num_frames} rows in {args.root}")
    folders = [args.policy] if args.policy else []
    for policy_type in args.train:
        output = args.root.with_name(f"{args.root.name}_{policy_type}")
        folders.append(str(train(args.root, policy_type, args.train_steps, output)))
    for folder in folders:
        metrics = evaluate(folder, args.sessions, args.episode_frames, args.seed)
        print(json.dumps({"policy": folder, **metrics}))


if __name__ == "__main__":
    main()
