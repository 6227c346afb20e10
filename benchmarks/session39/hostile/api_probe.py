import dataclasses

import pslog
from pslog.fusion import FusionOptions

s = pslog.read_session("s/sim.mcap")
cases = {
 "read_session(123)": lambda: pslog.read_session(123),
 "read_session(None)": lambda: pslog.read_session(None),
 "read_session(b'x')": lambda: pslog.read_session(b"s/sim.mcap"),
 "sync regularize=maybe": lambda: pslog.sync(s, "offset", regularize="maybe"),
 "sync estimate=123": lambda: pslog.sync(s, 123),
 "sync estimate=[]": lambda: pslog.sync(s, []),
 "sync search_s=True": lambda: pslog.sync(s, "offset", search_s=True),
 "fuse methods=123": lambda: pslog.fuse(s, 123),
 "fuse rig=123": lambda: pslog.fuse(s, "nearest", rig=123),
 "fuse options=dict": lambda: pslog.fuse(s, "nearest", options={"max_gap_s": 1}),
 "FusionOptions(max_gap_s=nan)": lambda: FusionOptions(max_gap_s=float("nan")),
 "FusionOptions(tolerance_s=nan)": lambda: FusionOptions(tolerance_s=float("nan")),
 "FusionOptions(tolerance_s=-1)": lambda: FusionOptions(tolerance_s=-1.0),
 "FusionOptions(noise_px=inf)": lambda: FusionOptions(noise_px=float("inf")),
 "FusionOptions(noise_px=1e-320)": lambda: FusionOptions(noise_px=1e-320),
 "FusionOptions(max_gap_s=1e-320)": lambda: pslog.fuse(s, "nearest", options=FusionOptions(max_gap_s=1e-320)),  # noqa: E501
 "fuse tolerance 1.0 s": lambda: pslog.fuse(s, "nearest", options=FusionOptions(tolerance_s=1.0)),
 "fuse clock_uncertainty='no'": lambda: pslog.fuse(s, "nearest", clock_uncertainty="no"),
 "evaluate(123)": lambda: pslog.evaluate(123, s.truth),
 "fuse(s.detections, rig='paper2')": lambda: pslog.fuse(s.detections, "nearest", rig="paper2"),
}

print([f.name for f in dataclasses.fields(FusionOptions)])
for name, f in cases.items():
    try:
        r = f()
        print(name, "-> OK", type(r).__name__, (len(r) if hasattr(r, "__len__") else ""))
    except pslog.errors.PslogError as e:
        print(name, "-> PslogError", type(e).__name__, str(e)[:150])
    except Exception as e:
        print(name, "-> OTHER", type(e).__name__, str(e)[:150])
