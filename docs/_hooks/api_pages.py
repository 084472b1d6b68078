"""MkDocs hook: the API reference pages, generated from one registry of public modules.

:data:`API_PAGES` maps each page ``api/<name>.md`` to its title, the guide that explains the
code, and the modules it renders (with mkdocstrings, from the docstrings); :data:`EXCLUDED` names
every module left out, each with the reason. ``tests/docs/test_api_registry.py`` fails when a
module under ``oasis_torchrl/`` is in neither, or when either names a module that is gone. The
nav in ``mkdocs.yml`` lists the pages in the same order (the strict build fails on a page that
is missing from it or a nav entry with no page).

The guides link to the source (``../../oasis_torchrl/client/``,
``../../oasis_torchrl/envs/specs.py``), which a forge shows as it is; on the site
:func:`on_page_markdown` points each such link at the module's section of its API page instead
(the pages exist only on the site).
"""

from __future__ import annotations

import posixpath
import re
from dataclasses import dataclass
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

PACKAGE = "oasis_torchrl"
ROOT = Path(__file__).resolve().parents[2]
"""The repository root, holding the package."""


@dataclass(frozen=True)
class ApiPage:
    """One API reference page: a title, the guide to read first and the modules it renders."""

    title: str
    guide: str
    modules: tuple[str, ...]


API_PAGES: dict[str, ApiPage] = {
    "envs": ApiPage(
        "Environments",
        "guides/env.md",
        (
            "oasis_torchrl",
            "oasis_torchrl.envs",
            "oasis_torchrl.envs.oasis_env",
            "oasis_torchrl.envs.embedded",
            "oasis_torchrl.envs.specs",
            "oasis_torchrl.envs.transforms",
            "oasis_torchrl.envs.factory",
            "oasis_torchrl.envs.episodes",
            "oasis_torchrl.envs.driving",
            "oasis_torchrl.envs.gym_adapter",
            "oasis_torchrl.envs.gym_vector",
            "oasis_torchrl.envs.per_frame",
            "oasis_torchrl.envs.capabilities",
        ),
    ),
    "rewards": ApiPage(
        "Rewards",
        "guides/env.md",
        (
            "oasis_torchrl.rewards",
            "oasis_torchrl.rewards.base",
            "oasis_torchrl.rewards.motion",
            "oasis_torchrl.rewards.motion_net",
            "oasis_torchrl.rewards.weights_file",
            "oasis_torchrl.rewards.depth_collision",
            "oasis_torchrl.rewards.depth_sources",
            "oasis_torchrl.rewards.depth_net",
            "oasis_torchrl.rewards.depth_models",
            "oasis_torchrl.rewards.ground_truth",
            "oasis_torchrl.rewards.shaping",
        ),
    ),
    "client": ApiPage(
        "Client",
        "guides/hosted.md",
        (
            "oasis_torchrl.client",
            "oasis_torchrl.client.sync_client",
            "oasis_torchrl.client.pool",
            "oasis_torchrl.client.pool_row",
            "oasis_torchrl.client.transport",
            "oasis_torchrl.client.session",
            "oasis_torchrl.client.types",
            "oasis_torchrl.client.errors",
            "oasis_torchrl.client.retry",
            "oasis_torchrl.client.channel",
            "oasis_torchrl.client.wire",
            "oasis_torchrl.client.decoding",
            "oasis_torchrl.client.background",
            "oasis_torchrl.client.health",
            "oasis_torchrl.client.ground_truth",
            "oasis_torchrl.client.scenes",
        ),
    ),
    "server": ApiPage(
        "Embedded server",
        "guides/server.md",
        (
            "oasis_torchrl.sim",
            "oasis_torchrl.sim.config",
            "oasis_torchrl.sim.launcher",
            "oasis_torchrl.sim.errors",
            "oasis_torchrl.sim.faults",
            "oasis_torchrl.film",
            "oasis_torchrl.video",
        ),
    ),
    "drivers": ApiPage(
        "Drivers",
        "guides/training.md",
        (
            "oasis_torchrl.drivers",
            "oasis_torchrl.drivers.base",
            "oasis_torchrl.drivers.loading",
            "oasis_torchrl.drivers.pretrained",
            "oasis_torchrl.drivers.autopilot",
            "oasis_torchrl.drivers.late_reaction",
            "oasis_torchrl.drivers.scripted",
            "oasis_torchrl.drivers.policy",
            "oasis_torchrl.drivers.folders",
            "oasis_torchrl.drivers.lerobot",
        ),
    ),
    "models": ApiPage(
        "Models",
        "guides/training.md",
        (
            "oasis_torchrl.models",
            "oasis_torchrl.models.config",
            "oasis_torchrl.models.network",
            "oasis_torchrl.models.encoder",
            "oasis_torchrl.models.distributions",
            "oasis_torchrl.models.actor_critic",
            "oasis_torchrl.models.privileged",
            "oasis_torchrl.models.checkpoint",
            "oasis_torchrl.models.depth",
            "oasis_torchrl.models.motion",
        ),
    ),
    "train": ApiPage(
        "Training",
        "guides/training.md",
        (
            "oasis_torchrl.train",
            "oasis_torchrl.train.pipeline",
            "oasis_torchrl.train.plan",
            "oasis_torchrl.train.stages",
            "oasis_torchrl.train.ppo",
            "oasis_torchrl.train.ppo_update",
            "oasis_torchrl.train.ppo_loss",
            "oasis_torchrl.train.bc",
            "oasis_torchrl.train.bc_data",
            "oasis_torchrl.train.batch_order",
            "oasis_torchrl.train.demonstrations",
            "oasis_torchrl.train.comparison",
            "oasis_torchrl.train.cards",
            "oasis_torchrl.train.stage_seconds",
            "oasis_torchrl.train.aux_replay",
            "oasis_torchrl.train.perception_warmup",
            "oasis_torchrl.train.shift",
            "oasis_torchrl.train.depth",
            "oasis_torchrl.train.motion",
            "oasis_torchrl.train.motion_chunks",
            "oasis_torchrl.train.motion_dataset",
            "oasis_torchrl.train.motion_checks",
            "oasis_torchrl.train.driven_rounds",
            "oasis_torchrl.allocator",
            "oasis_torchrl.atomic",
            "oasis_torchrl.closing",
        ),
    ),
    "evaluation": ApiPage(
        "Evaluation",
        "guides/training.md",
        (
            "oasis_torchrl.evaluation",
            "oasis_torchrl.evaluation.evaluator",
            "oasis_torchrl.evaluation.reports",
            "oasis_torchrl.evaluation.selection",
            "oasis_torchrl.evaluation.rollouts",
            "oasis_torchrl.evaluation.recorders",
            "oasis_torchrl.evaluation.side_by_side",
        ),
    ),
    "config": ApiPage(
        "Configs",
        "guides/training.md",
        (
            "oasis_torchrl.config",
            "oasis_torchrl.config.loading",
            "oasis_torchrl.config.presets",
            "oasis_torchrl.config.arguments",
            "oasis_torchrl.config.env",
            "oasis_torchrl.config.run",
            "oasis_torchrl.config.training",
            "oasis_torchrl.config.reward_networks",
            "oasis_torchrl.config.evaluation",
            "oasis_torchrl.config.pipeline",
            "oasis_torchrl.config.demonstrations",
            "oasis_torchrl.config.scenes",
            "oasis_torchrl.config.pretrained",
            "oasis_torchrl.config.recording",
            "oasis_torchrl.config.serving",
            "oasis_torchrl.config.policy_serving",
            "oasis_torchrl.config.ray",
            "oasis_torchrl.config.viewing",
            "oasis_torchrl.config.web",
            "oasis_torchrl.options",
            "oasis_torchrl.shipped",
        ),
    ),
    "data": ApiPage(
        "LeRobot datasets",
        "guides/lerobot.md",
        (
            "oasis_torchrl.data",
            "oasis_torchrl.data.recorder",
            "oasis_torchrl.data.writer",
            "oasis_torchrl.data.features",
            "oasis_torchrl.data.chunk_rows",
            "oasis_torchrl.data.episode_buffer",
            "oasis_torchrl.data.images",
            "oasis_torchrl.data.importer",
            "oasis_torchrl.data.loading",
            "oasis_torchrl.data.video_frames",
            "oasis_torchrl.data.quiet",
            "oasis_torchrl.video_fallback",
            "oasis_torchrl.data.combine",
            "oasis_torchrl.compat",
        ),
    ),
    "viz": ApiPage(
        "Rerun",
        "guides/rerun.md",
        (
            "oasis_torchrl.viz",
            "oasis_torchrl.viz.logger",
            "oasis_torchrl.viz.options",
            "oasis_torchrl.viz.hooks",
            "oasis_torchrl.viz.blueprint",
            "oasis_torchrl.viz.palette",
            "oasis_torchrl.viz.summary",
            "oasis_torchrl.viz.side_by_side",
            "oasis_torchrl.viz.topdown",
            "oasis_torchrl.viz.series",
            "oasis_torchrl.viz.images",
            "oasis_torchrl.viz.records",
            "oasis_torchrl.viz.recording",
            "oasis_torchrl.viz.replay",
            "oasis_torchrl.viz.lerobot_replay",
            "oasis_torchrl.viz.paths",
            "oasis_torchrl.viz.timelines",
            "oasis_torchrl.viz.titles",
            "oasis_torchrl.viz.worker",
            "oasis_torchrl.viz.writer",
        ),
    ),
    "web": ApiPage(
        "Drive page",
        "guides/browser.md",
        (
            "oasis_torchrl.web",
            "oasis_torchrl.web.app",
            "oasis_torchrl.web.server",
            "oasis_torchrl.web.session",
            "oasis_torchrl.web.takeover",
            "oasis_torchrl.web.recording",
            "oasis_torchrl.web.replay",
            "oasis_torchrl.web.messages",
            "oasis_torchrl.web.frames",
        ),
    ),
    "policy_server": ApiPage(
        "Policy server",
        "guides/policy_server.md",
        (
            "oasis_torchrl.remote",
            "oasis_torchrl.remote.policy",
            "oasis_torchrl.remote.errors",
            "oasis_torchrl.remote.features",
            "oasis_torchrl.remote.tensors",
            "oasis_torchrl.serving",
            "oasis_torchrl.serving.server",
            "oasis_torchrl.serving.served",
            "oasis_torchrl.serving.host",
            "oasis_torchrl.serving.batching",
            "oasis_torchrl.serving.limits",
            "oasis_torchrl.serving.sessions",
        ),
    ),
    "distributed": ApiPage(
        "Ray",
        "guides/ray.md",
        (
            "oasis_torchrl.distributed",
            "oasis_torchrl.distributed.ray_collection",
            "oasis_torchrl.distributed.ray_recording",
            "oasis_torchrl.distributed.sharded_recording",
            "oasis_torchrl.distributed.merge",
            "oasis_torchrl.distributed.placement",
            "oasis_torchrl.distributed.namespace_cluster",
        ),
    ),
    "protocol": ApiPage(
        "Protocol",
        "PROTOCOL.md",
        ("oasis_torchrl.protocol", "oasis_torchrl.proto"),
    ),
}
"""Page name (``api/<name>.md``) -> page, in the order of the nav."""

_SIM_INSIDE = (
    "the embedded server's inside: library code reaches it through the protocol or the "
    "launcher, never by import (the protocol page and the server guide describe its interface)"
)
_GENERATED = (
    "generated by protoc from the .proto beside it (griffe cannot read it; see PROTOCOL.md)"
)

EXCLUDED: dict[str, str] = {
    "oasis_torchrl.__main__": "`python -m oasis_torchrl`, the console script's shim",
    "oasis_torchrl.cli": "the console script: its flags come from the configs (Configs page)",
    "oasis_torchrl.commands": "one module per sub-command: the guides show them, --help the flags",
    "oasis_torchrl.proto.a2v_pb2": _GENERATED,
    "oasis_torchrl.proto.a2v_pb2_grpc": _GENERATED,
    "oasis_torchrl.proto.common_pb2": _GENERATED,
    "oasis_torchrl.proto.common_pb2_grpc": _GENERATED,
    "oasis_torchrl.proto.policy_pb2": _GENERATED,
    "oasis_torchrl.proto.policy_pb2_grpc": _GENERATED,
    "oasis_torchrl.proto.sim_pb2": _GENERATED,
    "oasis_torchrl.proto.sim_pb2_grpc": _GENERATED,
    "oasis_torchrl.sim.__main__": "`python -m oasis_torchrl.sim`, the server's shim",
    "oasis_torchrl.sim.auth": _SIM_INSIDE,
    "oasis_torchrl.sim.autopilot": _SIM_INSIDE,
    "oasis_torchrl.sim.encoding": _SIM_INSIDE,
    "oasis_torchrl.sim.render": _SIM_INSIDE,
    "oasis_torchrl.sim.scene": _SIM_INSIDE,
    "oasis_torchrl.sim.style": _SIM_INSIDE,
    "oasis_torchrl.sim.server": _SIM_INSIDE,
    "oasis_torchrl.sim.serving": _SIM_INSIDE,
    "oasis_torchrl.sim.session_world": _SIM_INSIDE,
    "oasis_torchrl.sim.sessions": _SIM_INSIDE,
    "oasis_torchrl.sim.simulator": _SIM_INSIDE,
    "oasis_torchrl.sim.validation": _SIM_INSIDE,
    "oasis_torchrl.sim.vehicle": _SIM_INSIDE,
    "oasis_torchrl.sim.worker": _SIM_INSIDE,
    "oasis_torchrl.sim.worker_pool": _SIM_INSIDE,
    "oasis_torchrl.sim.world": _SIM_INSIDE,
}
"""Module (or package, with everything under it) -> why it has no API page."""


def package_modules(root: Path) -> list[str]:
    """Every module of the package under ``root`` (the repository), as dotted names.

    Args:
        root: The repository root, holding ``oasis_torchrl/``.

    Returns:
        The dotted names, sorted; a package is named by its ``__init__``.
    """
    names = []
    for path in (root / PACKAGE).rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return sorted(names)


def exclusion_reason(module: str) -> str | None:
    """The reason ``module`` has no API page, or None when it should have one.

    Args:
        module: A dotted module name.

    Returns:
        The reason of the module's own entry or of the package above it, if any.

    Examples:
        >>> exclusion_reason("oasis_torchrl.sim.render.camera") == _SIM_INSIDE
        True
        >>> exclusion_reason("oasis_torchrl.envs") is None
        True
    """
    parts = module.split(".")
    for end in range(len(parts), 0, -1):
        reason = EXCLUDED.get(".".join(parts[:end]))
        if reason is not None:
            return reason
    return None


def page_markdown(page: ApiPage) -> str:
    """The Markdown of one API page: a title, a link to its guide, one directive per module.

    A package is rendered without members: its modules have their own sections.

    Args:
        page: The page.

    Returns:
        The page's Markdown source.
    """
    lines = [
        f"# {page.title}",
        "",
        f"Generated from the docstrings. Read the [guide](../{page.guide}) first.",
        "",
    ]
    for module in page.modules:
        lines.append(f"::: {module}")
        if (ROOT.joinpath(*module.split(".")) / "__init__.py").exists():
            lines += ["    options:", "      members: false"]
        lines.append("")
    return "\n".join(lines)


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add the generated ``api/<name>.md`` pages to the site's files."""
    for name, page in API_PAGES.items():
        files.append(File.generated(config, f"api/{name}.md", content=page_markdown(page)))
    return files


SOURCE_LINK = re.compile(
    r"\]\((?P<target>(?:\.\./)+" + PACKAGE + r"/[^)#\s]*)(?:#(?P<name>[\w.]+))?\)"
)
"""A Markdown link into the package's source, relative to the page, with an optional
``#Name`` of a member (a forge opens the file; the site goes to the member's section)."""


def module_of(path: str) -> str:
    """The dotted module a source path names: a package's folder or ``__init__.py``, a file.

    Examples:
        >>> module_of("oasis_torchrl/client/")
        'oasis_torchrl.client'
        >>> module_of("oasis_torchrl/envs/specs.py")
        'oasis_torchrl.envs.specs'
    """
    parts = path.strip("/").removesuffix(".py").split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def site_link(page_uri: str, target: str) -> str | None:
    """The site's link for a source link ``target`` of the page ``page_uri``: the module's
    section of the API page that renders it (None: no page renders it).

    Examples:
        >>> site_link("guides/env.md", "../../oasis_torchrl/envs/specs.py")
        '../api/envs.md#oasis_torchrl.envs.specs'
        >>> site_link("index.md", "../oasis_torchrl/client/")
        'api/client.md#oasis_torchrl.client'
        >>> site_link("guides/env.md", "../../oasis_torchrl/sim/render/") is None
        True
    """
    source = posixpath.normpath(posixpath.join("docs", posixpath.dirname(page_uri), target))
    module = module_of(source)
    for name, page in API_PAGES.items():
        if module in page.modules:
            start = posixpath.dirname(page_uri) or "."
            return f"{posixpath.relpath(f'api/{name}.md', start)}#{module}"
    return None


def on_page_markdown(markdown: str, page: Page, **_: object) -> str:
    """Point the page's links into the source at the API pages (unknown ones are left as they
    are, for the strict build to report)."""

    def replace(match: re.Match[str]) -> str:
        link = site_link(page.file.src_uri, match["target"])
        if link is None:
            return match.group(0)
        return f"]({link}.{match['name']})" if match["name"] else f"]({link})"

    return SOURCE_LINK.sub(replace, markdown)
