"""Session 29's leftovers of issue 10 through the real CLI: messages that named the wrong
command or stage."""

from __future__ import annotations

from pathlib import Path

import pytest

from pslog.rig import builtin_rig

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep29")
    (folder / "rig.toml").write_text(builtin_rig("paper3").to_toml(), encoding="utf-8")
    # cam1 sees a moving ball; cam2's and cam3's detections are 60,000 px off their images
    # (accepted by import: within its bound; no detection to a fit)
    rows = ["camera,time,u,v"]
    for i in range(90):
        t, cam = i / 90, f"cam{i % 3 + 1}"
        uv = (300 + 100 * t, 200 + 50 * t) if cam == "cam1" else (60000, 60000)
        rows.append(f"{cam},{t:.6f},{uv[0]!r},{uv[1]!r}")
    (folder / "far.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    done = run_pslog("import", "--rig", folder / "rig.toml", "--detections",
                     folder / "far.csv", "-o", folder / "far.mcap")
    assert done.code == 0, done.stderr
    return folder


@pytest.mark.parametrize("estimate", ["auto", "offset"])
def test_a_sync_whose_track_cannot_be_fitted_says_so_in_syncs_words(estimate, inputs,
                                                                    tmp_path):
    """Was "pslog sync: error: smooth: no stretch of the session is seen by two cameras":
    the trajectory fit's message with the fusion method's name. Now sync's context, and why
    two thirds of the detections were no detection."""
    before = fingerprint(inputs, tmp_path)
    line = assert_one_line_error(run_pslog(
        "sync", inputs / "far.mcap", "-o", tmp_path / "s.mcap", "--estimate", estimate), 1,
        contains=("pslog sync: error: the ball's track, on which the clocks are estimated, "
                  "cannot be fitted: no stretch of the session is seen by two cameras (one "
                  "camera cannot triangulate); 60 of 90 detections lie more than 10 image "
                  "sizes off their image and are no detection",))
    assert "smooth" not in line, line
    assert_untouched(before, inputs, tmp_path)


def test_a_message_index_opcode_flip_is_not_reported_as_lost_messages(tmp_path):
    """The first MessageIndex record after the sample's first chunk, its opcode flipped:
    ``recover`` skipped those index records (rebuilding the index) but reported them as
    "unreadable bytes 3122..3308, 1 on /camera/cam1/transform, 1 on ... (no valid record)",
    messages it had in fact kept (from the intact chunk before). Now it names them as that
    chunk's index, no message lost; every message is in the recovered file."""
    from pslog.log import read_session

    sample = Path(__file__).resolve().parents[2] / "samples" / "throw.mcap"
    data = bytearray(sample.read_bytes())
    pos, ops = 8, []
    while data[pos] != 0x0F:  # the data section's records, to DataEnd
        ops.append((pos, data[pos]))
        pos += 9 + int.from_bytes(data[pos + 1:pos + 9], "little")
    at = next(p for (p, op), (_, before) in zip(ops[1:], ops, strict=False)
              if op == 0x07 and before == 0x06)
    end = next(p for p, op in ops if p > at and op != 0x07)
    data[at] ^= 0xFF
    broken = tmp_path / "b.mcap"
    broken.write_bytes(bytes(data))
    fixed = tmp_path / "fixed.mcap"
    run = run_pslog("recover", broken, "-o", fixed)
    assert run.code == 0 and run.stderr == "", run.stderr
    assert (f"unreadable bytes {at}..{end} (the MessageIndex records of the chunk before, the "
            f"first one damaged in its opcode (0xf8); that chunk's messages are kept)"
            in run.stdout), run.stdout
    assert " on /camera" not in run.stdout.split("messages kept per topic")[0], run.stdout
    got, want = read_session(fixed), read_session(sample)
    assert got.detections.n_frames == want.detections.n_frames == 135
    assert got.rig.names == want.rig.names
    assert read_session(fixed).metadata == want.metadata
