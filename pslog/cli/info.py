"""``pslog info``: cameras, message counts, duration, rates, measured shutter offsets."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="SESSION.mcap", help="session file to summarise")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")


def run(args: argparse.Namespace) -> int:
    from pslog.errors import LogFormatError, shell_word
    from pslog.log import session_info

    info = session_info(args.session)
    if args.json:
        import json

        print(json.dumps(_jsonable(info), indent=2, allow_nan=False))
    else:
        print("\n".join(_text(info)))
    recover = f"run 'pslog recover {shell_word(args.session)} -o FIXED.mcap'"
    if info["truncated"] and info["still_recording"]:
        raise LogFormatError(f"{args.session} is incomplete: it may still be recording "
                             f"(modified {info['age_s']:.0f} s ago); if no recorder is "
                             f"writing it, {recover} to salvage it")
    if info["truncated"]:
        raise LogFormatError(f"{args.session}: {info['problem']}; {recover} to salvage it")
    if info["damaged"]:
        n = len(info["damaged"])
        what = "chunk" if all(d["chunk"] for d in info["damaged"]) else "part"
        raise LogFormatError(f"{args.session} has {n} damaged {what}{'s' if n > 1 else ''} "
                             f"(first at byte {info['damaged'][0]['start']}); {recover} to "
                             f"salvage every intact one")
    return 0


#: stretches without a frame listed per camera (the JSON has every one)
GAPS_SHOWN = 3


def _jsonable(value):
    """NaN (e.g. the rate of a camera without frames) becomes null: strict JSON."""
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_jsonable(v) for v in value]
    return value


def _fps(value: float, frames: int) -> str:
    """A measured rate, or why there is none (0 or 1 frame has no period)."""
    if value == value:
        return f"{value:.2f}"
    return "1 frame" if frames == 1 else "-"


def _pct(value: float) -> str:
    return "-" if value != value else f"{value:.1%}"


def _ms(seconds: float) -> str:
    # + 0.0: a -0.0 (or a value rounding to it) prints as 0.000, not -0.000
    return "-" if seconds != seconds else f"{round(seconds * 1e3, 3) + 0.0:.3f} ms"


def _damage(info: dict) -> list[str]:
    from pslog.log.recover import damage_line

    return [f"    {damage_line(d)}" for d in info["damaged"]]


def _text(info: dict) -> list[str]:
    if info["truncated"]:
        from pslog.log.recover import describe_salvage

        state = ("TRUNCATED or still being written" if info["still_recording"] else
                 "TRUNCATED" if info["problem"].startswith("the recording") else "DAMAGED")
        lines = [f"{info['path']}: {state} ({info['problem']})",
                 f"  intact data: {info['kept_bytes']} of {info['file_bytes']} bytes: "
                 f"{describe_salvage(info)}"]
        if info["damaged"]:
            lines.append(f"  unreadable ({len(info['damaged'])} part(s)):")
            lines += _damage(info)
        lines.append("  salvageable messages:")
        lines += [f"    {t}: {n}" for t, n in info["topics"].items()]
        lines.append(f"  {info['hint']}")
        return lines
    start = info["start_s"]
    lines = [
        f"{info['path']}",
        f"  format {info['format_version']}, timing {info['timing']}, rig "
        f"{info['rig'] or '-'}, created {info['created_utc']} by {info['creator']}",
        f"  source: {info['source'] or '-'}",
        f"  duration {info['duration_s']:.3f} s"
        + ("" if start is None else f" (t = {start:.6f} .. {info['end_s']:.6f} s)")
        + f", {info['frames']} frames, {info['candidates']} candidates, "
          f"{info['images']} images",
    ]
    from pslog.tables import format_table

    # 'detected' read 100 % on a session whose ball was missed in half the frames: a static
    # distractor is a candidate in every frame (session 33). The frames with any candidate,
    # with one that moves, and the candidates per frame say what is known without truth.
    table = format_table(
        ("camera", "frames", "fps measured", "nominal", "offset measured",
         f"rig ({info['timing']})", "any cand.", "moving", "cand/frame", "images"),
        [(c["name"], f"{c['frames']}", _fps(c["fps_measured"], c["frames"]),
          f"{c['fps_nominal']:g}",
          _ms(c["offset_measured_s"]), _ms(c["offset_nominal_s"]),
          _pct(c["detection_rate"]), _pct(c["moving_rate"]),
          "-" if c["candidates_per_frame"] != c["candidates_per_frame"]
          else f"{c['candidates_per_frame']:.2f}", f"{c['images']}") for c in info["cameras"]])
    lines += ["  " + line for line in table.splitlines()]
    lines.append("  (any cand.: frames with at least one candidate; moving: with one off every "
                 "static spot, the ball's detection rate when nothing else moves)")
    for c in info["cameras"]:
        for spot in c["static_spots"]:
            lines.append(f"  {c['name']}: a candidate that does not move, at ({spot['u']:.1f}, "
                         f"{spot['v']:.1f}) px in {spot['share']:.1%} of its frames (a static "
                         f"object, or the ball at rest): not counted as moving")
    from pslog.log.info import gap_text

    # a camera unplugged halfway read as a plain 60.00 fps row with fewer frames (walk41)
    gaps = info.get("camera_gaps", [])
    for name in dict.fromkeys(g["camera"] for g in gaps):
        mine = [g for g in gaps if g["camera"] == name]
        lines += [f"  {gap_text(gap)}" for gap in mine[:GAPS_SHOWN]]
        if len(mine) > GAPS_SHOWN:
            more = len(mine) - GAPS_SHOWN
            lines.append(f"  {name}: {more} more such stretch{'es' if more > 1 else ''} "
                         f"('pslog info --json' lists them)")
    off = info.get("offsets_off", [])
    if off:
        from pslog.errors import shell_word

        said = ", ".join(f"{o['camera']} measured {o['measured_s'] * 1e3:.3f} ms, rig "
                         f"{o['rig_s'] * 1e3:.3f} ms" for o in off)
        path = shell_word(info["path"])
        if info["clock_corrected"] and not info.get("clock_synced", True):
            # (walk42: a new recording with the rig 'pslog rig show synced.mcap' wrote, its
            # clocks an earlier session's: webcams' offsets move at every start)
            lines.append(f"  shutters off the rig's offsets ({said}), measured on the times "
                         f"the rig's clock model corrects, a model not estimated on this "
                         f"session (given with its rig, e.g. an earlier session's 'pslog "
                         f"sync'): the cameras' clocks may have moved since; 'pslog sync "
                         f"{path} -o synced.mcap' estimates them on this one")
        elif info["clock_corrected"]:
            # (walk42: a synced session of webcams whose rig planned no phases, offsets 0,
            # was told "camera clocks off" though its clock model corrects them: the phases
            # measured are on the corrected times, where the cameras really fire)
            lines.append(f"  shutters off the rig's offsets ({said}), measured on the times "
                         f"the rig's clock model corrects: the cameras fire there, not where "
                         f"the rig's offsets plan (fusion runs on the corrected times; type "
                         f"A's and the filter's tests of a missed frame count in the offsets' "
                         f"spacing; 'pslog sync' without --phases keep writes the measured "
                         f"ones; or 'pslog rig show {path} > rig.toml', edit the offsets, "
                         f"'pslog fuse {path} --rig rig.toml')")
        else:
            lines.append(f"  shutters off the rig's offsets ({said}): camera clocks off, or the "
                         f"rig's offsets not the cameras'; 'pslog sync {path} -o synced.mcap' "
                         f"estimates the clocks")
    if info["clock_corrected"]:
        lines.append("  clock model (true = logged + offset + drift * logged + readout * v / "
                     "height; applied when fusing):")
        for c in info["cameras"]:
            lines.append(f"    {c['name']:<8} offset {c['clock_offset_s'] * 1e3:+.4f} ms, drift "
                         f"{c['clock_drift_ppm']:+.3f} ppm, readout "
                         f"{c['readout_s'] * 1e3:.4f} ms")
    if info["clock_origin_ns"]:
        from pslog.log.csvio import format_time

        lines.append(f"  session clock origin {format_time(info['clock_origin_ns'])} s "
                     f"(original times = session times + origin; 'pslog export' "
                     f"--detections and --csv add it, its other formats keep the session "
                     f"clock)")
    tracks = ", ".join(f"{m} ({n} points)" for m, n in info["tracks"].items()) or "none"
    lines.append(f"  truth: {'yes' if info['truth'] else 'no'}; tracks: {tracks}; "
                 f"events: {info['events']} (the recorder's notes, topic /events, e.g. a "
                 f"camera that stopped)")
    lines.append(f"  (measured offsets are relative to {info['offset_reference']}, placed at its "
                 f"rig offset" + ("; measured on times the clock model corrects"
                                  if info["clock_corrected"] else "") + ")")
    lines.append("  messages per topic:")
    lines += [f"    {t}: {n}" for t, n in info["topics"].items()]
    lines += [f"  columnar table {name} {state}; read from the per-frame messages instead"
              for name, state in info.get("tables", {}).items() if state != "ok"]
    if info["damaged"]:
        what = "chunk(s)" if all(d["chunk"] for d in info["damaged"]) else "part(s)"
        lines.append(f"  DAMAGED: {len(info['damaged'])} {what} fail their checks; the "
                     f"figures above leave them out:")
        lines += _damage(info)
        lines.append(f"  {info['hint']}")
    return lines
