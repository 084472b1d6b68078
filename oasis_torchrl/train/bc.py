"""Behaviour cloning of the oasis driving policy on a LeRobot dataset.

The same pieces as ``lerobot-train --policy.type=oasis``: LeRobot's ``make_policy`` (features
from the dataset), the plugin's processors (resize and normalisation), ``policy.forward`` as
the loss and the policy's AdamW preset. What differs: the dataset is decoded once into memory
(:class:`~oasis_torchrl.train.bc_data.InMemoryBCDataset`; ``dataset.cache=false`` streams
from the videos like ``lerobot-train``), random-shift augmentation
(:mod:`~oasis_torchrl.train.shift`), TorchRL loggers, tqdm, and an evaluation in the env at the
end. The output folder is a LeRobot policy folder (``save_pretrained`` weights, config and
processors): it loads with ``OasisPolicy.from_pretrained``, in ``lerobot-train --policy.path``,
and as a PPO warm start (``init_from``). Config: :class:`~oasis_torchrl.config.BCConfig`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig, OmegaConf
from torch.utils.data import DataLoader
from torchrl.record.loggers import get_logger
from tqdm import tqdm

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.config import save_config
from oasis_torchrl.config.run import resume_point
from oasis_torchrl.data.features import IMAGE_PREFIX
from oasis_torchrl.drivers.folders import lerobot_plugin, load_net
from oasis_torchrl.evaluation import EvalReport, Evaluator
from oasis_torchrl.models import make_actor_critic
from oasis_torchrl.models.privileged import PRIVILEGED_KEY
from oasis_torchrl.protocol import FRONT_CROP
from oasis_torchrl.train.batch_order import StepBatches
from oasis_torchrl.train.bc_data import InMemoryBCDataset
from oasis_torchrl.train.shift import random_shift

logger = logging.getLogger(__name__)


@dataclass
class BCResult:
    """The trained LeRobot policy, its folder and its evaluation (if one was run).

    Example:
        >>> train_bc(load_config("bc", ["dataset.root=drives"])).policy_dir  # doctest: +SKIP
        PosixPath('outputs/bc/policy')
    """

    policy: Any
    policy_dir: Path
    final_eval: EvalReport | None
    final_loss: float


def open_dataset(cfg: DictConfig, policy_config: Any) -> Any:
    """The LeRobot dataset of ``cfg.dataset`` with the policy's delta timestamps (the frames
    and next actions each sample needs).

    Example:
        >>> dataset = open_dataset(cfg.dataset, policy_config)  # doctest: +SKIP
        >>> dataset[0]["action"].shape  # doctest: +SKIP
        torch.Size([4, 2])
    """
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    from oasis_torchrl.data.loading import dataset_repo_id, default_video_backend

    if not cfg.root:
        raise ValueError("dataset.root is required: the LeRobot dataset folder to clone")
    root = Path(cfg.root)
    repo_id = dataset_repo_id(root, cfg.repo_id)
    meta = LeRobotDatasetMetadata(repo_id, root=root)
    return LeRobotDataset(
        repo_id,
        root=root,
        episodes=list(cfg.episodes) if cfg.episodes is not None else None,
        delta_timestamps=resolve_delta_timestamps(policy_config, meta),
        video_backend=default_video_backend(),
    )


def policy_inputs(
    features: dict[str, dict[str, Any]], cameras: Sequence[str] | None, front_crop: float | None
) -> dict[str, Any]:
    """The policy's input features from a dataset's ``features``: every one but the action,
    with only ``cameras``' images where given; a ``front_crop`` camera needs its fraction.

    Example:
        >>> video = {"dtype": "video", "shape": (64, 96, 3), "names": ["height", "width", "c"]}
        >>> features = {f"{IMAGE_PREFIX}{c}": video for c in ("front", "front_crop")}
        >>> sorted(policy_inputs(features, ["front"], None))
        ['observation.images.front']
        >>> policy_inputs(features, None, None)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: the dataset's cameras include 'front_crop': set policy.front_crop to ...
    """
    from lerobot.configs import FeatureType
    from lerobot.utils.feature_utils import dataset_to_policy_features

    inputs = {
        key: feature
        for key, feature in dataset_to_policy_features(features).items()
        if feature.type is not FeatureType.ACTION
    }
    if cameras is not None:
        known = [key.removeprefix(IMAGE_PREFIX) for key in inputs if key.startswith(IMAGE_PREFIX)]
        unknown = sorted(set(cameras) - set(known))
        if unknown:
            raise ValueError(f"dataset.cameras {unknown} are not in the dataset (it has {known})")
        inputs = {
            key: feature
            for key, feature in inputs.items()
            if not key.startswith(IMAGE_PREFIX) or key.removeprefix(IMAGE_PREFIX) in cameras
        }
    if f"{IMAGE_PREFIX}{FRONT_CROP}" in inputs and front_crop is None:
        raise ValueError(
            f"the dataset's cameras include '{FRONT_CROP}': set policy.front_crop to the "
            "env.front_crop it was recorded with, or leave it out with dataset.cameras"
        )
    return inputs


PARTIAL_POLICY = "checkpoints/last"
"""Where the policy so far is saved every ``train.save_every`` steps, with its
:data:`TRAINING_STATE`. ``policy/`` is written once, at the end, so a run whose ``policy/``
exists finished (the main job reuses such folders)."""

TRAINING_STATE = "training_state.pt"
"""What ``resume`` continues from, beside the partial policy: the step, the weights, the
optimizer's state, the smoothed loss and the torch generator's state."""


class BCTrainer:
    """One behaviour-cloning run; :meth:`run` trains, saves and evaluates.

    Args:
        cfg: the resolved :class:`~oasis_torchrl.config.BCConfig` (with overrides).
        resume: a saved training state to continue from (``latest``: this run's own), whatever
            ``cfg.resume`` says; None: as ``cfg.resume`` says.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> cfg = load_config("bc", ["dataset.root=drives"])  # doctest: +SKIP
        >>> BCTrainer(cfg).run().policy_dir  # doctest: +SKIP
    """

    def __init__(self, cfg: DictConfig, *, resume: str | None = None) -> None:
        from lerobot.policies.factory import make_policy, make_pre_post_processors

        plugin = lerobot_plugin()
        self.cfg = cfg
        self.resume = resume or cfg.resume
        self.output_dir = Path(cfg.output_dir)
        torch.manual_seed(cfg.seed)
        self.policy_config = plugin.OasisConfig.from_settings(
            OmegaConf.to_container(cfg.policy), cfg.optim
        )
        dataset = open_dataset(cfg.dataset, self.policy_config)
        self.policy_config.input_features = policy_inputs(
            dataset.meta.features, cfg.dataset.cameras, cfg.policy.front_crop
        )
        self.policy = make_policy(self.policy_config, ds_meta=dataset.meta)
        if cfg.init_from:  # fine-tune (e.g. a DAgger round) instead of starting afresh
            self.policy.model.warm_start(load_net(cfg.init_from))
        self.preprocessor, self.postprocessor = make_pre_post_processors(
            self.policy_config, dataset_stats=dataset.meta.stats
        )
        cached = None
        shift = partial(random_shift, pad=cfg.train.shift_pad) if cfg.train.shift_pad else None
        if cfg.dataset.cache:  # frames kept at the policy's size: no resize per batch
            size = tuple(self.policy_config.image_size)
            cached = InMemoryBCDataset(
                dataset,
                image_size=size,
                progress=cfg.progress,
                frame_transform=shift,
                camera_keys=list(self.policy_config.image_features),
            )
        # The cache shifts the frames while they are bytes; LeRobot's dataset gives floats.
        self.shift_in_loop = shift if cached is None else None
        data = dataset if cached is None else cached
        self.batch_order = StepBatches(len(data), cfg.train.batch_size, cfg.seed)
        self.loader = DataLoader(
            data,
            batch_sampler=self.batch_order,
            num_workers=cfg.train.num_workers,
            # its workers' seeds from its own generator: starting it draws none from torch's
            generator=torch.Generator().manual_seed(cfg.seed),
            collate_fn=None if cached is None else cached.collate,
        )
        self.optimizer = self.policy_config.get_optimizer_preset().build(
            list(self.policy.get_optim_params())
        )
        self.logger = get_logger(
            cfg.logger.backend,
            logger_name=str(self.output_dir / "logs"),
            experiment_name=cfg.logger.exp_name,
        )
        self.image_keys = [key for key in self.policy_config.image_features]
        self.done_steps, self.average = self._resume() if self.resume else (0, float("nan"))

    def _resume(self) -> tuple[int, float]:
        """Load the training state ``resume`` names: ``latest``, this run's
        ``checkpoints/last``, or another such folder (:func:`resume_point`); the steps it had
        taken and its smoothed loss.

        Raises:
            FileNotFoundError: the folder holds no training state to resume.
        """
        folder = resume_point(self.resume, self.output_dir / PARTIAL_POLICY)
        path = Path(folder) / TRAINING_STATE
        if not path.exists():
            raise FileNotFoundError(f"nothing to resume: {path} does not exist")
        state = torch.load(path, weights_only=False)
        self.policy.load_state_dict(state["policy"])
        self.optimizer.load_state_dict(state["optimizer"])
        torch.set_rng_state(state["rng"])
        logger.info("resuming behaviour cloning at step %d from %s", state["step"], path)
        return int(state["step"]), float(state["average"])

    def run(self) -> BCResult:
        """Train ``train.steps`` steps, save the policy folder, evaluate if configured."""
        save_config(self.cfg, self.output_dir / "config.yaml")
        loss = self.train()
        policy_dir = self.save(self.output_dir / "policy")
        final = self._evaluate() if self.cfg.eval.episodes else None
        return BCResult(self.policy, policy_dir, final, loss)

    def train(self) -> float:
        """Take ``train.steps`` gradient steps; the loss, smoothed over the last ~50 steps."""
        cfg = self.cfg.train
        clip = self.policy_config.optimizer_grad_clip_norm
        parameters = list(self.policy.get_optim_params())
        self.policy.train()
        average = self.average
        # a resumed run takes the batches the run that never stopped takes
        self.batch_order.first_step = self.done_steps
        batches = iter(self.loader)
        with tqdm(
            range(self.done_steps + 1, cfg.steps + 1),
            desc="bc",
            unit="step",
            initial=self.done_steps,
            total=cfg.steps,
            disable=not self.cfg.progress,
        ) as bar:
            for step in bar:
                batch = self._preprocessed(next(batches))
                if self.shift_in_loop is not None:
                    for key in self.image_keys:
                        batch[key] = self.shift_in_loop(batch[key])
                loss, info = self.policy.forward(batch)
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                grad_norm = torch.nn.utils.clip_grad_norm_(parameters, clip)
                self.optimizer.step()
                value = loss.item()
                average = value if math.isnan(average) else 0.98 * average + 0.02 * value
                if step % cfg.log_every == 0 or step == cfg.steps:
                    self.logger.log_scalar("bc/loss", value, step=step)
                    self.logger.log_scalar("bc/grad_norm", float(grad_norm), step=step)
                    if "aux_loss" in info:
                        self.logger.log_scalar("bc/aux_loss", info["aux_loss"], step=step)
                    bar.set_postfix(loss=f"{average:.4f}")
                if cfg.save_every and step % cfg.save_every == 0 and step < cfg.steps:
                    self.save_partial(step, average)
        return average

    def save_partial(self, step: int, average: float) -> Path:
        """Save the policy so far and its training state to :data:`PARTIAL_POLICY`."""
        path = self.save(self.output_dir / PARTIAL_POLICY)
        state = {
            "step": step,
            "average": average,
            "policy": self.policy.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "rng": torch.get_rng_state(),
        }
        with written_whole(path / TRAINING_STATE) as partial:  # a stop keeps the last state
            torch.save(state, partial)
        return path

    def _preprocessed(self, raw: dict[str, Any]) -> dict[str, Any]:
        """The batch through the policy's preprocessor, the privileged state kept beside it
        (LeRobot's processors drop the columns they do not know)."""
        batch = self.preprocessor(raw)
        if PRIVILEGED_KEY in raw:
            batch[PRIVILEGED_KEY] = raw[PRIVILEGED_KEY]
        return batch

    def save(self, path: Path) -> Path:
        """Write the LeRobot policy folder: weights, config and both processors."""
        self.policy.save_pretrained(path)
        self.preprocessor.save_pretrained(path)
        self.postprocessor.save_pretrained(path)
        return path

    def _evaluate(self) -> EvalReport:
        net = self.policy.model.eval()
        image_size = tuple(net.config.image_size)
        with Evaluator(
            self.cfg.env,
            self.cfg.eval,
            image_size=image_size,
            frame_stack=net.config.frames,
            front_crop=net.config.front_crop,
            progress=self.cfg.progress,
            name=self.cfg.logger.exp_name,
        ) as evaluator:
            report = evaluator.evaluate(make_actor_critic(net).policy)
        for name, value in report.summary().items():
            self.logger.log_scalar(f"eval/{name}", value, step=self.cfg.train.steps)
        logger.info("behaviour-cloning evaluation: %s", report.summary())
        return report


def train_bc(cfg: DictConfig, *, resume: str | None = None) -> BCResult:
    """Run behaviour cloning as configured (:class:`~oasis_torchrl.config.BCConfig`), resuming
    ``resume`` if given; see :class:`BCTrainer`.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> train_bc(load_config("bc", ["dataset.root=drives"]))  # doctest: +SKIP
    """
    return BCTrainer(cfg, resume=resume).run()
