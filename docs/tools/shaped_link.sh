#!/usr/bin/env bash
# The shaped-link table of docs/performance.md ("Links that are not loopback"): two network
# namespaces joined by a veth pair whose two ends are rate-limited with tc's token bucket (tbf),
# the launcher (its router, the interface and coarse nodes) in one, the three subdomain node
# processes in the other, started by hand as on a second machine. For each link rate and each
# linear stage (condensed, PGD), one run of the scene, recording off; prints wall time,
# iterations and the bytes that crossed the link per iteration (both directions, as the veth end
# in the launcher's namespace counts them, headers included). Needs root (namespaces); every namespace is
# removed at the end, also on failure.
#
#   [DELAYS="none 0 0.1 0.5"] docs/tools/shaped_link.sh [glissade binary] [scene] [rates...]
#
# e.g. docs/tools/shaped_link.sh target/release/glissade launch/scenes/stratified.toml 10gbit 1gbit
#
# DELAYS (default "none"): for each value but "none", the subdomain processes reach the router
# through docs/tools/delay_proxy.py in their namespace, which delays every byte by that many
# milliseconds each way (for kernels without netem); "0" is the proxy without delay, the control
# for its own cost.
set -euo pipefail
glissade=$(realpath "${1:-target/release/glissade}")
scene=$(realpath "${2:-launch/scenes/stratified.toml}")
shift $(($# < 2 ? $# : 2))
rates=("${@:-10gbit 1gbit}")
delays=(${DELAYS:-none})
proxy_py=$(realpath "$(dirname "$0")/delay_proxy.py")
[[ $(id -u) == 0 ]] || { echo "needs root to create network namespaces" >&2; exit 1; }
work=$(mktemp -d)
a=glissade-link-a-$$ b=glissade-link-b-$$ va=gla$$ vb=glb$$
cleanup() {
    # A failed run's logs first.
    for log in "$work"/out-*/*.log; do
        [[ -e $log && $keep_logs == 1 ]] && { echo "--- $log" >&2; cat "$log" >&2; }
    done
    ip link del "$va" 2>/dev/null || true
    ip netns pids "$a" 2>/dev/null | xargs -r kill 2>/dev/null || true
    ip netns pids "$b" 2>/dev/null | xargs -r kill 2>/dev/null || true
    ip netns del "$a" 2>/dev/null || true
    ip netns del "$b" 2>/dev/null || true
    rm -rf "$work"
}
keep_logs=1
trap cleanup EXIT
ip netns add "$a"
ip netns add "$b"
ip link add "$va" type veth peer name "$vb"
ip link set "$va" netns "$a"
ip link set "$vb" netns "$b"
ip -n "$a" addr add 10.214.0.1/24 dev "$va"
ip -n "$b" addr add 10.214.0.2/24 dev "$vb"
for ns in "$a" "$b"; do ip -n "$ns" link set lo up; done
ip -n "$a" link set "$va" up
ip -n "$b" link set "$vb" up
endpoint=tcp/10.214.0.1:17447

# Bits per second of a tc rate such as 10gbit or 500mbit.
tc_bits() {
    local n=${1%%[a-z]*} unit=${1##*[0-9]}
    case $unit in
        gbit) echo $((n * 1000000000)) ;;
        mbit) echo $((n * 1000000)) ;;
        *) echo "rate $1: give it in gbit or mbit" >&2; exit 1 ;;
    esac
}

echo "| link | added delay each way (ms) | linear stage | iterations | wall time (s) | per iteration (ms) | link bytes per iteration (MB) |"
echo "|---|---|---|---:|---:|---:|---:|"
for rate in ${rates[*]}; do
    # The bucket holds 1 ms at the rate; packets wait at most 100 ms for tokens.
    bits=$(tc_bits "$rate")
    for pair in "$a $va" "$b $vb"; do
        set -- $pair
        tc -n "$1" qdisc replace dev "$2" root tbf rate "$rate" burst $((bits / 8000)) latency 100ms
    done
    for delay in ${delays[*]}; do
    for stage in condensed pgd; do
        sc="$work/$stage.toml"
        # Every field over the link: no shared memory (the namespaces share /dev/shm).
        if [[ $stage == pgd ]]; then
            # `enabled = false` of the [solver.pgd] table only.
            awk '/^\[/ {pgd = ($0 == "[solver.pgd]")} pgd && /^enabled = false/ {sub(/false/, "true"); on = 1} {print} END {exit !on}' \
                "$scene" >"$sc" || { echo "$scene has no [solver.pgd] enabled = false to turn on" >&2; exit 1; }
        else
            cp "$scene" "$sc"
        fi
        grep -q '^\[network\]' "$sc" && { echo "$scene has a [network] table: leave it out" >&2; exit 1; }
        printf '\n[network]\nshared_memory = false\n' >>"$sc"
        run=link-$stage-$rate-${delay/./_}-$$
        out="$work/out-$run"
        mkdir -p "$out"
        connect=$endpoint
        proxy=
        if [[ $delay != none ]]; then
            ip netns exec "$b" python3 "$proxy_py" --listen 127.0.0.1:17448 --to "${endpoint#tcp/}" \
                --delay-ms "$delay" >"$out/proxy.log" 2>&1 &
            proxy=$!
            for _ in $(seq 100); do grep -q listening "$out/proxy.log" && break; sleep 0.1; done
            grep -q listening "$out/proxy.log" || { echo "the delay proxy did not start:" >&2; cat "$out/proxy.log" >&2; exit 1; }
            connect=tcp/127.0.0.1:17448
        fi
        link_bytes() {
            local d=/sys/class/net/$va/statistics
            ip netns exec "$a" sh -c "echo \$((\$(cat $d/tx_bytes) + \$(cat $d/rx_bytes)))"
        }
        bytes0=$(link_bytes)
        start=$(date +%s.%N)
        ip netns exec "$a" "$glissade" run "$sc" --no-record --quiet --verbose --run-id "$run" --out "$out" \
            --listen "$endpoint" --remote subdomain:0,subdomain:1,subdomain:2 >"$out/launcher.log" 2>&1 &
        launcher=$!
        nodes=()
        for i in 0 1 2; do
            cred="$out/$run-subdomain-$i.credentials"
            for _ in $(seq 600); do [[ -e $cred ]] && break; sleep 0.1; done
            [[ -e $cred ]] || { echo "no credentials for subdomain node $i" >&2; cat "$out/launcher.log" >&2; exit 1; }
            ip netns exec "$b" "$glissade" node subdomain --run "$run" --connect "$connect" --index "$i" \
                --credentials "$cred" >"$out/node-$i.log" 2>&1 &
            nodes+=($!)
        done
        wait "$launcher" || { echo "the run failed:" >&2; cat "$out/launcher.log" >&2; exit 1; }
        for n in "${nodes[@]}"; do wait "$n"; done
        end=$(date +%s.%N)
        bytes=$(($(link_bytes) - bytes0))
        if [[ -n $proxy ]]; then kill "$proxy"; wait "$proxy" 2>/dev/null || true; fi
        python3 - "$out" "$rate" "$delay" "$stage" "$start" "$end" "$bytes" <<'EOF'
import glob, json, sys
out, rate, delay, stage = sys.argv[1:5]
start, end, link = (float(t) for t in sys.argv[5:8])
d = json.load(open(glob.glob(out + "/*.summary.json")[0]))
n = d["iterations"]
# Everything that crossed the link during the run (set-up, the scene, the final solutions
# included), per iteration.
print(f"| {rate} | {delay} | {stage} | {n} ({d['verdict']}) | {end - start:.1f} | {d['solve_s'] / max(n, 1) * 1e3:.0f} | {link / max(n, 1) / 1e6:.1f} |")
EOF
    done
    done
done
keep_logs=0
