#!/usr/bin/env bash
# The farm path on a real Slurm: a single-node cluster on this machine
# (munged, slurmctld, slurmd; a generated slurm.conf; every state, spool,
# log and socket under one temp dir), the demo shot planned and submitted at
# a tiny resolution, outputs compared byte for byte with a local
# `throng render` + `throng comp`, `farm status` exit 0; a deep plan
# (`--deep`) likewise against `render --deep` + `comp --deep`; then a task killed
# mid-render (scancel), `status` naming it failed with its log, a re-submit,
# and completion. Fails with the reason when the scheduler cannot start.
#
# Usage: .ci/slurm_test.sh [path/to/throng]   (run as root: it may apt-get
# install slurm-wlm and munge, and munged/slurmd run as root)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=$(realpath "${1:-target/debug/throng}")
[ -x "$bin" ] || { echo "FAIL: no throng binary at $bin (cargo build --locked first)"; exit 1; }
started=$SECONDS
fail() { echo "FAIL: $*"; exit 1; }

if ! command -v slurmctld >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
    echo "installing Debian's slurm-wlm and munge"
    apt-get update -qq || fail "apt-get update failed: cannot install Slurm"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null ||
        fail "apt-get install slurm-wlm munge failed"
fi

tmp=$(mktemp -d /tmp/throng-slurm.XXXXXX)
pids=()
cleanup() {
    status=$?
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    # slurmd forks slurmstepd per job; give them a moment, then make sure.
    sleep 1
    for f in "$tmp"/run/*.pid; do [ -f "$f" ] && kill -9 "$(cat "$f")" 2>/dev/null || true; done
    for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done
    if [ "$status" -ne 0 ]; then
        for log in "$tmp"/log/*.log; do echo "---- $log (tail)"; tail -n 20 "$log" || true; done
    fi
    rm -rf "$tmp"
    exit "$status"
}
trap cleanup EXIT
mkdir -p "$tmp"/{munge,run,log,state,spool}
chmod 700 "$tmp/munge"

# ---- munge: our own key and socket, not /etc/munge or /run/munge
dd if=/dev/urandom of="$tmp/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge/munge.key"
sock="$tmp/munge/munge.sock"
munged --force --key-file="$tmp/munge/munge.key" --socket="$sock" \
    --pid-file="$tmp/run/munged.pid" --log-file="$tmp/log/munged.log" \
    --seed-file="$tmp/munge/munged.seed" || fail "munged would not start (see $tmp/log/munged.log)"
pids+=("$(cat "$tmp/run/munged.pid")")
munge --socket="$sock" -n | unmunge --socket="$sock" >/dev/null || fail "munge round trip failed: munged is not answering"

# ---- slurm.conf: one node named after this host, with this machine's cores and memory
host=$(hostname -s)
node=$(slurmd -C | head -n 1) # NodeName=<host> CPUs=... RealMemory=...
case "$node" in NodeName=*) ;; *) fail "slurmd -C gave no node line: $node" ;; esac
port=$((20000 + RANDOM % 20000))
export SLURM_CONF="$tmp/slurm.conf"
cat >"$SLURM_CONF" <<EOF
ClusterName=throngci
SlurmctldHost=$host
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$sock
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/run/slurmctld.pid
SlurmdPidFile=$tmp/run/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MinJobAge=600
SchedulerParameters=sched_interval=2
$node State=UNKNOWN
PartitionName=throng Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -i || fail "slurmctld would not start (see $tmp/log/slurmctld.log)"
sleep 1
pids+=("$(cat "$tmp/run/slurmctld.pid" 2>/dev/null || echo 0)")
slurmd || fail "slurmd would not start (see $tmp/log/slurmd.log)"
sleep 1
pids+=("$(cat "$tmp/run/slurmd.pid" 2>/dev/null || echo 0)")
for _ in $(seq 1 30); do
    state=$(sinfo -h -n "$host" -o %T 2>/dev/null || true)
    [ "$state" = idle ] && break
    sleep 1
done
[ "$state" = idle ] || fail "node $host is not idle after 30 s (sinfo: '${state:-no answer}'); scheduler did not come up"
echo "slurm: single-node cluster up on $host ($node), port $port, in $(( SECONDS - started )) s"

# Waits up to $2 seconds for `farm status $1` to exit 0.
wait_done() {
    local plan=$1 limit=$2 t0=$SECONDS
    while ! "$bin" farm status "$plan" >"$tmp/status.txt" 2>&1; do
        if (( SECONDS - t0 > limit )); then
            cat "$tmp/status.txt"; squeue -t all || true
            fail "plan $plan not done after $limit s"
        fi
        sleep 1
    done
}

# ---- 1. the demo on Slurm, byte-identical to a local render + comp
work="$tmp/work"
"$bin" farm plan demo/shot.toml --frames 1024-1025 --chunk 1 --spp 1 --resolution 32x18 --out "$work/farm"
"$bin" farm submit "$work/farm/plan.json" --engine slurm | tee "$tmp/submit.txt"
grep -q "slurm job [0-9]" "$tmp/submit.txt" || fail "submit printed no job ids"
wait_done "$work/farm/plan.json" 90
echo "slurm: demo plan done in $(( SECONDS - started )) s"
m="$work/farm/demo.layers.json"
"$bin" render demo/shot.toml --manifest "$m" --frames 1024-1025 --spp 1 --resolution 32x18 --progress off --out "$work/local" >/dev/null
mkdir -p "$work/local/comp"
for f in 1024 1025; do
    "$bin" comp "$work/local" --frame $f --manifest "$m" --out "$work/local/comp/demo.comp.$f.exr" >/dev/null
done
(cd "$work/farm/render" && find . -name '*.exr' | sort | xargs sha256sum) >"$tmp/farm.sums"
(cd "$work/local" && find . -name '*.exr' | sort | xargs sha256sum) >"$tmp/local.sums"
diff "$tmp/farm.sums" "$tmp/local.sums" || fail "farm outputs differ from the local render + comp"
n=$(wc -l <"$tmp/farm.sums")
[ "$n" -eq 10 ] || fail "expected 10 EXRs (4 layers x 2 frames + 2 comps), found $n"
"$bin" farm status "$work/farm/plan.json" >/dev/null || fail "farm status does not exit 0 on a finished plan"
echo "slurm: $n EXRs byte-identical to local render + comp; farm status exit 0"

# ---- 1b. a deep plan (--deep): render tasks write deep files beside their
# flat ones, the comp the deep comp; byte-identical to a local
# `render --deep` + `comp --deep` (one frame, 32x18)
"$bin" farm plan demo/shot.toml --frames 1024 --chunk 1 --spp 1 --resolution 32x18 --deep --out "$work/deep" >/dev/null
"$bin" farm submit "$work/deep/plan.json" --engine slurm >/dev/null
wait_done "$work/deep/plan.json" 90
m="$work/deep/demo.layers.json"
"$bin" render demo/shot.toml --manifest "$m" --frames 1024 --spp 1 --resolution 32x18 --deep --progress off --out "$work/deep_local" >/dev/null
mkdir -p "$work/deep_local/comp"
"$bin" comp "$work/deep_local" --frame 1024 --manifest "$m" --out "$work/deep_local/comp/demo.comp.1024.exr" --deep >/dev/null
(cd "$work/deep/render" && find . -name '*.deep.exr' | sort | xargs sha256sum) >"$tmp/deep_farm.sums"
(cd "$work/deep_local" && find . -name '*.deep.exr' | sort | xargs sha256sum) >"$tmp/deep_local.sums"
diff "$tmp/deep_farm.sums" "$tmp/deep_local.sums" || fail "farm deep outputs differ from the local render --deep + comp --deep"
n=$(wc -l <"$tmp/deep_farm.sums")
[ "$n" -eq 5 ] || fail "expected 5 deep EXRs (4 layers + the deep comp), found $n"
echo "slurm: deep plan: $n deep EXRs byte-identical to local render --deep + comp --deep"

# ---- 2. kill a render task mid-render, status names it, re-submit completes
kplan="$work/kill/plan.json"
"$bin" farm plan demo/shot.toml --frames 1024-1025 --chunk 2 --spp 4 --resolution 640x360 --retries 0 --out "$work/kill" >/dev/null
"$bin" farm submit "$kplan" --engine slurm >"$tmp/submit2.txt"
victim=render.crowd0.0
job=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["jobs"][sys.argv[2]])' "$work/kill/farm/slurm.json" $victim)
t0=$SECONDS
until grep -q "^render: frame" "$work/kill/logs/$victim.log" 2>/dev/null ||
      grep -q "attempt 1" "$work/kill/logs/$victim.log" 2>/dev/null; do
    (( SECONDS - t0 > 60 )) && { squeue -t all; fail "$victim (job $job) never started"; }
    sleep 0.2
done
sleep 0.5
scancel "$job"
echo "slurm: cancelled $victim (job $job) mid-render"
t0=$SECONDS
while :; do
    set +e; "$bin" farm status "$kplan" >"$tmp/status2.txt" 2>&1; rc=$?; set -e
    grep -q "^$victim  *failed" "$tmp/status2.txt" && ! grep -q " running " "$tmp/status2.txt" && break
    (( SECONDS - t0 > 60 )) && { cat "$tmp/status2.txt"; fail "status never reported $victim failed"; }
    sleep 1
done
[ "$rc" -ne 0 ] || fail "farm status exits 0 with a failed task"
grep "^$victim" "$tmp/status2.txt"
vlog="$work/kill/logs/$victim.log"
! grep -q "task $victim done" "$vlog" || fail "$victim finished before the cancel: not a mid-render kill"
echo "slurm: $victim log at the kill: $(grep -c '^render: frame' "$vlog") of 2 frames done"
grep -q "^$victim .*log .*$victim.log" "$tmp/status2.txt" || fail "status does not name the failed task's log"
"$bin" farm submit "$kplan" --engine slurm | tee "$tmp/resubmit.txt"
grep -q "render.crowd0 array 0" "$tmp/resubmit.txt" || fail "re-submit did not run $victim again"
if grep -q "render.set\|render.crowd1\|render.crowd2" "$tmp/resubmit.txt"; then
    fail "re-submit ran tasks that were done"
fi
wait_done "$kplan" 90
echo "slurm: after the kill, re-submit completed the shot; status exit 0"
echo "slurm test passed in $(( SECONDS - started )) s"
