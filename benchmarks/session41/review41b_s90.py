"""review41b: motion_period's cost and answer on a 90-minute session (s39match/s90.mcap),
the best-scored candidates as the observations, the rig's clocks."""
import sys
import time

from pslog import read_session
from pslog.estimation.sync import motion_period
from pslog.fusion._prepare import default_max_gap_s

s = read_session(sys.argv[1] if len(sys.argv) > 1 else "/work/s39match/s90.mcap")
obs = s.detections.best()
t0 = time.process_time()
p = motion_period(obs, s.rig, default_max_gap_s(s.rig))
print(f"{len(obs)} obs, period {p}, {time.process_time() - t0:.2f} CPU s")
