# the after runs of session 36 (smooth only: the filter's code is unchanged)
O=benchmarks/session36/out
P=/work/main/.venv/bin/python
export PYTHONPATH=.
$P benchmarks/bench_dirty.py --more --validity --methods smooth --first-seed 46100 > $O/after_46100.txt 2>&1
for s in 48000 48300 48600; do
  $P benchmarks/bench_dirty.py --more --validity --methods smooth --first-seed $s > $O/after_$s.txt 2>&1
done
$P benchmarks/bench_dirty.py --more --validity --methods smooth --first-seed 48000 --fps 60 > $O/after_48000_60.txt 2>&1
