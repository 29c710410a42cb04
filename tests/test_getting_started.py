"""docs/getting-started.md's walk-through: its commands, read from the page.

The command lines of the console blocks of its section "Your first hour, step by step" are
commands of gcs; tests/test_getting_started_virtual.py runs them as they stand, in order,
against the simulated drone on the virtual clock.
"""

from __future__ import annotations

import re

from synthetic import ROOT

PAGE = ROOT / "docs" / "getting-started.md"
SECTION = "## Your first hour, step by step"


def walkthrough_commands(text: str) -> list[str]:
    """The command lines of the section's console blocks, in order (comments dropped)."""
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    commands = []
    for block in re.findall(r"```console\n(.*?)```", section, flags=re.S):
        for line in block.splitlines():
            line = line.split("  #", 1)[0].strip()
            if line and not line.startswith("#"):
                commands.append(line)
    return commands


def test_the_walkthrough_is_commands_of_gcs() -> None:
    commands = walkthrough_commands(PAGE.read_text())
    assert len(commands) >= 7 and all(c.startswith("gcs ") for c in commands), commands
    assert commands[0].startswith("gcs fly") and "--check" in commands[0]
