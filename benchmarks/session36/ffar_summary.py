# ruff: noqa: E501
"""Session 36 (ffar36): bench_dirty --more --validity --methods filter outputs, before (main)
against after (this branch): per configuration the far points (clean / added by faults), the
worst faults/clean ratio per rig and the pooled mean errors.

    python benchmarks/session36/ffar_summary.py DIR SEEDS... (files DIR/{main,wt-ffar36}_SEED_CFG.txt)"""
import re
import sys
from collections import defaultdict

d, seeds = sys.argv[1], sys.argv[2:]
row = re.compile(r"^\| ([\w@]+) \| filter \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \(([^;]+); data ([\d.]+)\) \| [\d.]+ \| (\d+) .*?/ (\d+) ")
for cfg in ("30", "60", "m"):
    for tree in ("main", "wt-ffar36"):
        far_c = far_a = 0
        ratios = defaultdict(list)
        means = defaultdict(list)
        for s in seeds:
            for line in open(f"{d}/{tree}_{s}_{cfg}.txt"):
                m = row.match(line)
                if m:
                    rig = m[1]
                    far_c += int(m[8])
                    far_a += int(m[9])
                    ratios[rig].append(float(m[5]))
                    means[rig].append((float(m[2]), float(m[3])))
        print(f"{cfg:>2} {tree:10} far clean {far_c} added {far_a}; worst session ratio per rig (max over seeds): "
              + ", ".join(f"{r} {max(v):.2f}" for r, v in ratios.items())
              + "; mean faults mm: " + ", ".join(f"{r} {sum(b for _, b in v)/len(v):.3f}" for r, v in means.items()))
