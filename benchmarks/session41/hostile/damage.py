"""Session 41's damage sweep (helper hostile41): a small recorded session with images and its
fused output, each cut at random byte offsets and each given random byte flips (seed 66xxx),
then every reading command run on every damaged file.

Each command runs in a child forked from one warmed process (``pslog.cli.main``, the modules
already imported: a real process would spend most of its time importing), with a timeout; a
child's uncaught exception prints its traceback as the interpreter would. Outcomes: ok /
ok-notes (exit 0), error1/error2 (one line), TRACEBACK, MULTILINE, HANG, BADCODE; and for
every run whether the damaged input changed (INPUT-CHANGED) or a file was left beside the
outputs (LEFTOVER).

Run: python damage.py WORK N_CUTS N_FLIPS SEED  (WORK holds rec.mcap and fused.mcap)."""

from __future__ import annotations

import hashlib
import os
import signal
import sys
import time
import traceback
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

os.environ.setdefault("PSLOG_PROGRESS", "off")
from pslog.cli import main

work = Path(sys.argv[1])
n_cuts, n_flips, seed = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
only = sys.argv[5].split(",") if len(sys.argv) > 5 else None
TIMEOUT = 90.0


def run_child(argv: list[str], cwd: Path) -> tuple[int | None, str, str]:
    out, err = cwd / ".out", cwd / ".err"
    pid = os.fork()
    if pid == 0:  # child
        code = 1
        try:
            os.chdir(cwd)
            fo, fe = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC), \
                os.open(err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(fo, 1)
            os.dup2(fe, 2)
            try:
                code = main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            except BaseException:
                traceback.print_exc()
                code = 1
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code if isinstance(code, int) else 1)
    start = time.monotonic()
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() - start > TIMEOUT:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return None, "", ""
        time.sleep(0.01)
    code = os.waitstatus_to_exitcode(status)
    o = out.read_text(errors="backslashreplace")
    e = err.read_text(errors="backslashreplace")
    out.unlink()
    err.unlink()
    return code, o, e


def classify(code, out, err) -> str:
    lines = [x for x in err.splitlines() if x.strip()]
    if code is None:
        return "HANG"
    if "Traceback" in err or "Traceback" in out or "Warning:" in err:
        return "TRACEBACK"
    if code == 0:
        return "ok" if not lines else "ok-notes"
    if code in (1, 2):
        return f"error{code}" if len(lines) == 1 else "MULTILINE"
    return f"BADCODE{code}"


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


COMMANDS = {
    "info": lambda f: ["info", f],
    "fuse": lambda f: ["fuse", f, "-o", "o_fused.mcap"],
    "sync": lambda f: ["sync", f, "-o", "o_synced.mcap"],
    "eval": lambda f: ["eval", f],
    "export": lambda f: (["export", f, "--csv", "o.csv"] if "fused" in f.name
                         else ["export", f, "--detections", "o.csv"]),
    "view": lambda f: ["view", f, "--save", "o.rrd"],
    "recover": lambda f: ["recover", f, "-o", "o_rec.mcap"],
}
OUTPUTS = {"o_fused.mcap", "o_synced.mcap", "o.csv", "o.rrd", "o_rec.mcap"}


def count_messages(path: Path) -> int:
    from mcap.reader import make_reader

    with open(path, "rb") as h:
        return sum(1 for _ in make_reader(h).iter_messages())


_CHUNKS: dict[Path, list[tuple[int, int, int]]] = {}


def intact_messages(source: Path, label: str) -> int:
    """Messages in the chunks the damage left whole: (start, end, count) of each chunk from
    the intact file's summary; a cut keeps those ending before it, a flip all but the one
    holding the byte (a flip outside every chunk: all of them)."""
    from mcap.reader import make_reader

    if source not in _CHUNKS:
        with open(source, "rb") as h:
            summary = make_reader(h).get_summary()
        with open(source, "rb") as h:
            counts = []
            for c in summary.chunk_indexes:
                h.seek(c.chunk_start_offset)
                blob = h.read(c.chunk_length)
                import io

                from mcap.stream_reader import StreamReader
                n = 0
                try:
                    for r in StreamReader(io.BytesIO(b"\x89MCAP0\r\n" + blob),
                                          skip_magic=False, emit_chunks=False).records:
                        n += type(r).__name__ == "Message"
                except Exception:  # (the end of the lone chunk)
                    pass
                counts.append(n)
        _CHUNKS[source] = [(c.chunk_start_offset, c.chunk_start_offset + c.chunk_length, n)
                           for c, n in zip(summary.chunk_indexes, counts, strict=True)]
    at = int(label.split("@")[1])
    if label.startswith("cut"):
        return sum(n for a, b, n in _CHUNKS[source] if b <= at)
    return sum(n for a, b, n in _CHUNKS[source] if not a <= at < b)


def warm_parent() -> None:
    """Every command once on the intact files in this process, so that the forked children
    start with the modules imported and the kernels loaded (else each child loads them)."""
    import contextlib
    import io
    import shutil

    folder = work / "warm"
    folder.mkdir(exist_ok=True)
    here = os.getcwd()
    os.chdir(folder)
    try:
        for source in (work / "rec.mcap", work / "fused.mcap"):
            for make in COMMANDS.values():
                with contextlib.redirect_stdout(io.StringIO()), \
                        contextlib.redirect_stderr(io.StringIO()):
                    main([str(a) for a in make(source)] + ["--force"] * 0)
                for name in OUTPUTS:
                    if (folder / name).exists():
                        (folder / name).unlink()
    finally:
        os.chdir(here)
        shutil.rmtree(folder)


rng = np.random.default_rng(seed)
tally: dict[str, Counter] = defaultdict(Counter)
bad: list[str] = []
sources = [work / "rec.mcap", work / "fused.mcap"]
case = 0
started = time.monotonic()
warm_parent()
print(f"parent warmed in {time.monotonic() - started:.1f} s", flush=True)
for source in sources:
    data = source.read_bytes()
    damaged = []
    intact_messages(source, "cut@0")  # (its chunks)
    big = [(a, b) for a, b, _n in _CHUNKS[source] if b - a > 100_000]  # (image chunks)

    def offset(low: int, data=data, big=big) -> int:
        """A third of the offsets outside the image chunks (the records every reader
        needs), the rest anywhere."""
        while True:
            at = int(rng.integers(low, len(data)))
            if rng.random() > 1 / 3 or not any(a <= at < b for a, b in big):
                return at

    for _ in range(n_cuts):
        at = offset(1)
        damaged.append((f"cut@{at}", data[:at]))
    for _ in range(n_flips):
        at = offset(0)
        b = bytearray(data)
        b[at] ^= int(rng.integers(1, 256))
        damaged.append((f"flip@{at}", bytes(b)))
    for label, blob in damaged:
        case += 1
        folder = work / "cases" / f"{source.stem}-{label}"
        folder.mkdir(parents=True, exist_ok=True)
        f = folder / source.name
        f.write_bytes(blob)
        before = digest(f)
        for name, make in COMMANDS.items():
            if only and name not in only:
                continue
            argv = [str(a) for a in make(f)]
            code, out, err = run_child(argv, folder)
            kind = classify(code, out, err)
            if digest(f) != before:
                kind += "+INPUT-CHANGED"
            outs = [p for p in folder.iterdir() if p.name in OUTPUTS]
            left = [p.name for p in folder.iterdir() if p.name != f.name
                    and p.name not in OUTPUTS]
            if left:
                kind += "+LEFTOVER"
            if code not in (0, None) and outs:
                kind += "+OUTPUT-ON-ERROR"
            if name == "recover" and code == 0:
                got = count_messages(folder / "o_rec.mcap")
                want = intact_messages(source, label)
                tally["recover-kept"]["all" if got >= want else "LOST"] += 1
                if got < want:
                    kind += f"+LOST({got}<{want})"
            tally[name][kind] += 1
            if kind not in ("ok", "ok-notes", "error1", "error2"):
                bad.append(f"{kind} {source.name} {label} {name}: {err.strip()[-400:]!r}")
            for p in outs:
                p.unlink()
        print(f"{case} {source.name} {label}: done {time.monotonic() - started:.0f} s",
              flush=True)
        import shutil
        shutil.rmtree(folder)
for name, c in tally.items():
    print(name, dict(c))
print("\n".join(bad))
