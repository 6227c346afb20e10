"""What the old-against-new equality tools (``fusion_equality.py``, ``smooth_equality.py``)
share: running their ``--dump`` under a git revision's ``pslog`` and under this tree's, and
walking the two dumps' outputs field by field."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def dumps(script: str, ref: str, extra: list[str]) -> tuple[dict, dict]:
    """The outputs ``script --dump PATH *extra`` writes (a pickle) under ``ref``'s pslog
    (``git archive``, in a temporary folder) and under this tree's: (old, new)."""
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref, "pslog"],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        old, new = os.path.join(tmp, "old.pkl"), os.path.join(tmp, "new.pkl")
        script = str(Path(script).resolve())
        env = dict(os.environ, PYTHONPATH=tmp)
        subprocess.run([sys.executable, script, "--dump", old, *extra], env=env, check=True,
                       cwd=tmp)
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        subprocess.run([sys.executable, script, "--dump", new, *extra], env=env, check=True,
                       cwd=tmp)
        with open(old, "rb") as f_old, open(new, "rb") as f_new:
            return pickle.load(f_old), pickle.load(f_new)


def field_pairs(a: dict, b: dict, unlike: list) -> Iterator[tuple]:
    """``(output, field, value in a, value in b)`` of every field two outputs of one name
    both have; an output whose fields differ (or a string output that differs: a message
    instead of fields) is printed and appended to ``unlike``."""
    assert a.keys() == b.keys()
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, str) or isinstance(y, str):
            if x != y:
                print("DIFF", key, x, y)
                unlike.append(key)
            continue
        if x.keys() != y.keys():
            print("FIELDS", key, set(x) ^ set(y))
            unlike.append(key)
            continue
        for f in x:
            yield key, f, x[f], y[f]
