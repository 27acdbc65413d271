"""``pip install "fingerfit[all]"`` installs every optional extra's packages."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_all_lists_every_extras_packages() -> None:
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    every = {req for name, reqs in extras.items() if name not in ("all", "test") for req in reqs}
    assert set(extras["all"]) == every


def test_readme_names_the_extra_of_each_command_that_needs_one() -> None:
    readme = (ROOT / "README.md").read_text()
    for command, extra in (("stream", "live"), ("retarget", "retarget"), ("view", "view")):
        assert f"`{command}`: `{extra}`" in readme, command
    assert 'pip install "fingerfit[all]"' in readme
