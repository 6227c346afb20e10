"""``pslog info``: cameras, message counts, duration, rates, measured shutter offsets."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="SESSION.mcap", help="session file to summarise")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")


def run(args: argparse.Namespace) -> int:
    from pslog.errors import LogFormatError
    from pslog.log import session_info

    info = session_info(args.session)
    if args.json:
        import json

        print(json.dumps(_jsonable(info), indent=2, allow_nan=False))
    else:
        print("\n".join(_text(info)))
    if info["truncated"]:
        raise LogFormatError(f"{args.session} is truncated; run 'pslog recover "
                             f"{args.session} -o FIXED.mcap' to salvage it")
    return 0


def _jsonable(value):
    """NaN (e.g. the rate of a camera without frames) becomes null: strict JSON."""
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_jsonable(v) for v in value]
    return value


def _pct(value: float) -> str:
    return "-" if value != value else f"{value:.1%}"


def _ms(seconds: float) -> str:
    return "-" if seconds != seconds else f"{seconds * 1e3:.3f} ms"


def _text(info: dict) -> list[str]:
    if info["truncated"]:
        from pslog.log.recover import describe_salvage

        lines = [f"{info['path']}: TRUNCATED (the recording did not finish)",
                 f"  complete data: {info['kept_bytes']} of {info['file_bytes']} bytes: "
                 f"{describe_salvage(info)}",
                 "  salvageable messages:"]
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
        "  camera   frames  fps(meas/nom)    offset measured / nominal  detected  images",
    ]
    for c in info["cameras"]:
        lines.append(
            f"  {c['name']:<8} {c['frames']:>6}  {c['fps_measured']:6.2f} / {c['fps_nominal']:<6g}"
            f"  {_ms(c['offset_measured_s']):>11} / {_ms(c['offset_nominal_s']):<11}"
            f"  {_pct(c['detection_rate']):>7}  {c['images']:>6}")
    tracks = ", ".join(f"{m} ({n} points)" for m, n in info["tracks"].items()) or "none"
    lines.append(f"  truth: {'yes' if info['truth'] else 'no'}; tracks: {tracks}; "
                 f"events: {info['events']}")
    lines.append("  messages per topic:")
    lines += [f"    {t}: {n}" for t, n in info["topics"].items()]
    return lines
