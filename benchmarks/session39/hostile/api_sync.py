import pslog

s = pslog.read_session("s/sim.mcap")
for v in [0.0, -0.001, float("nan"), float("inf"), 1e-323, "abc", 1e-13]:
    try:
        r = pslog.sync(s, "offset", search_s=v)
        print(repr(v), "OK", [round(c.offset * 1e3, 3) for c in r.rig.cameras] if hasattr(r, "rig") else r)  # noqa: E501
    except pslog.errors.PslogError as e:
        print(repr(v), "PslogError", type(e).__name__, e)
    except Exception as e:
        print(repr(v), "OTHER", type(e).__name__, e)
