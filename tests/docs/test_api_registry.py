"""Every module under ``oasis_torchrl/`` is on an API page or excluded with a reason, once."""

from __future__ import annotations

from collections import Counter

import pytest
import yaml

from ._hooks import ROOT, load_hook

pytest.importorskip("mkdocs", reason="the docs extra is not installed: pip install -e '.[docs]'")

registry = load_hook("api_pages")


def documented() -> list[str]:
    return [module for page in registry.API_PAGES.values() for module in page.modules]


def test_every_module_is_documented_or_excluded_with_a_reason() -> None:
    on_pages = set(documented())
    missing = [
        module
        for module in registry.package_modules(ROOT)
        if module not in on_pages and registry.exclusion_reason(module) is None
    ]
    assert not missing, f"add these modules to an API page or to EXCLUDED: {missing}"


def test_no_module_is_both_documented_and_excluded_nor_on_two_pages() -> None:
    twice = [module for module, count in Counter(documented()).items() if count > 1]
    assert not twice
    both = [module for module in documented() if registry.exclusion_reason(module) is not None]
    assert not both


def test_the_registry_names_only_modules_that_exist() -> None:
    modules = set(registry.package_modules(ROOT))
    packages = {module.rsplit(".", 1)[0] for module in modules}
    gone = [name for name in [*documented(), *registry.EXCLUDED] if name not in modules | packages]
    assert not gone, f"remove these modules from docs/_hooks/api_pages.py: {gone}"
    assert all(reason.strip() for reason in registry.EXCLUDED.values())


def test_the_nav_lists_the_api_pages_in_the_registry_order() -> None:
    nav = yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]
    api = next(entry["API reference"] for entry in nav if "API reference" in entry)
    assert api == [f"api/{name}.md" for name in registry.API_PAGES]


def test_each_page_links_its_guide_and_renders_its_modules() -> None:
    for page in registry.API_PAGES.values():
        assert (ROOT / "docs" / page.guide).is_file(), page.guide
        markdown = registry.page_markdown(page)
        assert all(f"::: {module}\n" in markdown for module in page.modules)
