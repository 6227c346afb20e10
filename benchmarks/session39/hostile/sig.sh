#!/bin/bash
# sig.sh SIGNAL DELAY OUTPUT ARGS... : run pslog with ARGS, signal after DELAY, report
set -m
sig=$1; d=$2; out=$3; shift 3
dir=$(dirname $out)
before=$(sha256sum $out 2>/dev/null | cut -c1-12)
PYTHONPATH=/work/wt-hostile /work/main/.venv/bin/python -m pslog.cli "$@" > /tmp/h39/sig.out 2>/tmp/h39/sig.err &
pid=$!
sleep $d; kill -$sig $pid; wait $pid; rc=$?
after=$(sha256sum $out 2>/dev/null | cut -c1-12)
echo "rc=$rc sig=$sig d=$d out before=$before after=$after :: $*"
sed 's/^/   E| /' /tmp/h39/sig.err | head -5
ls -a $dir | grep -iE "partial|tmp" | sed 's/^/   L| /'
