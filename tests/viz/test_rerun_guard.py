"""The viewer's import guard: a missing or other rerun is one line naming the extra."""

from __future__ import annotations

import sys
import types

import pytest

from eslam.errors import ConfigError
from eslam.viz.rerun_viewer import import_rerun


def test_missing_rerun_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # import fails
    with pytest.raises(ConfigError, match=r'pip install "eslam\[viewer\]"'):
        import_rerun()


def test_another_rerun_version_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rerun", types.SimpleNamespace(__version__="0.42.1"))
    with pytest.raises(ConfigError, match=r"0\.42\.1 is installed.*written for 0\.41"):
        import_rerun()
