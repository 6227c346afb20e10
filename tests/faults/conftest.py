"""Fixtures of the fault-injection suite."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest


@pytest.fixture
def work(inputs, tmp_path) -> Path:
    """A fresh copy of the module's ``inputs`` folder (each module defines ``inputs``), so a
    case that breaks its promises cannot spoil the next one."""
    folder = tmp_path / "w"
    shutil.copytree(inputs, folder)
    return folder

