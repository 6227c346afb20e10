"""``recorders``' public names are imported on first use (PEP 562)."""

from __future__ import annotations

import subprocess
import sys

import pytest

import recorders


def test_every_public_name_is_there_and_is_the_submodules():
    from recorders import detect, record, redetect, render, synthetic

    where = {"detect": detect, "record": record, "redetect": redetect, "render": render,
             "synthetic": synthetic}
    for name in recorders.__all__:
        value = getattr(recorders, name)
        assert value is getattr(where[recorders._WHERE[name]], name)
    assert set(recorders.__all__) <= set(dir(recorders))
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        recorders.nothing  # noqa: B018


def test_redetect_does_not_import_the_recorder_renderer_or_simulation():
    """``pslog redetect`` needs the detector only: importing ``recorders.redetect`` in a fresh
    interpreter leaves the recorder, the renderer and the simulation unloaded (each was
    imported by the package's ``__init__``, about 20 ms of every run)."""
    code = ("import sys, recorders.redetect, recorders.detect; "
            "print(sorted(m for m in ('recorders.record', 'recorders.render', "
            "'recorders.synthetic', 'pslog.simulation') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
