"""MkDocs hook: docstrings' doctest examples render as code, Sphinx roles as code spans.

The project's docstrings put ``>>>`` examples anywhere in their text (pytest runs them all), but
Markdown reads such a line as prose, so ``x[0][1]`` becomes a dangling reference link that fails
the strict build. This hook adds a Markdown preprocessor that fences every run of doctest lines
(the ``>>>``/``...`` lines and the output that follows, up to a blank line) as ``pycon`` code,
for the pages and for mkdocstrings' docstrings alike. Lines already inside a fence or an indented
code block are left as they are. Sphinx roles (``:class:`~a.B```) become code spans (``B``).
"""

from __future__ import annotations

import re

from markdown import Extension, Markdown
from markdown.preprocessors import Preprocessor
from mkdocs.config.defaults import MkDocsConfig
from mkdocs.plugins import event_priority

_PROMPT = re.compile(r"^(?P<indent> {0,3})>>>( |$)")
_FENCE = re.compile(r"^\s*(```|~~~)")
_ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc|obj):`(?P<tilde>~?)(?P<target>[^`]+)`")


def _role_to_code(match: re.Match[str]) -> str:
    target = match.group("target").lstrip(".")
    return f"`{target.rsplit('.', 1)[-1] if match.group('tilde') else target}`"


def unroll_roles(line: str) -> str:
    """A line with every Sphinx cross-reference role written as a code span.

    Args:
        line: One Markdown line.

    Returns:
        The line; ``~`` keeps the last name only, as Sphinx shows it.

    Examples:
        >>> unroll_roles("see :class:`~oasis_torchrl.envs.OasisEnv` and :mod:`.errors`")
        'see `OasisEnv` and `errors`'
    """
    return _ROLE.sub(_role_to_code, line)


def fence_doctests(lines: list[str]) -> list[str]:
    """Wrap every run of doctest lines outside code in a ``pycon`` fence.

    Args:
        lines: Markdown source lines.

    Returns:
        The lines, each doctest run after a blank line, between fence lines of its indentation.

    Examples:
        >>> fence_doctests(["Text.", ">>> x[0]", "1", "", "More."])
        ['Text.', '', '```pycon', '>>> x[0]', '1', '```', '', 'More.']
    """
    fenced: list[str] = []
    in_fence = False
    index = 0
    while index < len(lines):
        line = lines[index]
        if _FENCE.match(line):
            in_fence = not in_fence
        prompt = None if in_fence else _PROMPT.match(line)
        if prompt is None:
            fenced.append(line if in_fence else unroll_roles(line))
            index += 1
            continue
        indent = prompt.group("indent")
        end = index
        while end < len(lines) and lines[end].strip():
            end += 1
        fenced += ["", f"{indent}```pycon", *lines[index:end], f"{indent}```"]
        index = end
    return fenced


class _DocstringMarkdown(Preprocessor):
    def run(self, lines: list[str]) -> list[str]:
        return fence_doctests(lines)


class DocstringMarkdownExtension(Extension):
    """Python-Markdown extension registering the preprocessor."""

    def extendMarkdown(self, md: Markdown) -> None:
        # Before fenced_code_block (25) so the fences it adds are parsed as code.
        md.preprocessors.register(_DocstringMarkdown(md), "docstring_markdown", 28)


@event_priority(100)  # before mkdocstrings reads the extension list
def on_config(config: MkDocsConfig) -> MkDocsConfig:
    """Add the extension to the site's (and so mkdocstrings') Markdown extensions."""
    config.markdown_extensions.append(DocstringMarkdownExtension())
    return config
