#!/usr/bin/env bash
# The scaling table of docs/performance.md ("Many subdomains"): generated laminates of 18, 100,
# 300 and 1000 subdomains (10 × 10 QUA8 each, N = 100), each run in-process, as processes with
# fields through shared memory (what the launcher chooses for an unrecorded run on one machine) and
# as processes over TCP (through the launcher's router), recording off. Prints one markdown row per
# size and mode; bus bytes per iteration count the messages sent every iteration. Time per
# iteration is given per subdomain and per interface: most of an iteration's work is on the
# interfaces' fields, and a small laminate has fewer interfaces per subdomain (its outer edges).
#
#   docs/tools/scaling.sh [glissade binary] [work folder]
#
# Use a release build, on a machine where no other glissade runs. Peak memory is the largest sum
# of the resident memory of every process named glissade, sampled every 0.1 s.
set -euo pipefail
glissade=${1:-target/release/glissade}
work=${2:-$(mktemp -d)}
mkdir -p "$work"

# Sum of the resident memory (kB) of every process named glissade, sampled until $1 exits.
peak_rss() {
    local peak=0 now
    while kill -0 "$1" 2>/dev/null; do
        now=$(ps -C glissade -o rss= | awk '{s += $1} END {print s + 0}')
        ((now > peak)) && peak=$now
        sleep 0.1
    done
    echo "$peak"
}

echo "| subdomains | interfaces | mode | iterations | set-up (s) | iterations (s) | median iteration from the 3rd (ms) | per subdomain (ms) | per interface (ms) | peak memory (GB) | bus bytes per iteration (MB) |"
echo "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"
for size in "3 6" "5 20" "10 30" "20 50"; do
    set -- $size
    scene="$work/laminate-$1x$2.toml"
    [[ -e $scene ]] || "$glissade" generate laminate --plies "$1" --per-ply "$2" -o "$scene" >/dev/null
    # The interfaces as `glissade check` counts them (contact between plies, perfect within).
    interfaces=$("$glissade" check "$scene" | sed -n 's/.* subdomains, \([0-9]*\) interfaces.*/\1/p')
    tcp="$work/laminate-$1x$2-tcp.toml"
    [[ -e $tcp ]] || printf '%s\n\n[network]\nshared_memory = false\n' "$(cat "$scene")" >"$tcp"
    for mode in in-process shared-memory tcp; do
        out="$work/out-$1x$2-$mode"
        rm -rf "$out"
        flags=(--no-record --quiet --out "$out")
        [[ $mode == in-process ]] && flags+=(--in-process) || flags+=(--verbose)
        file=$scene
        [[ $mode == tcp ]] && file=$tcp
        "$glissade" run "$file" "${flags[@]}" >"$work/log-$1x$2-$mode" 2>&1 &
        pid=$!
        peak=$(peak_rss "$pid")
        wait "$pid" || { echo "the $mode run of $scene failed:" >&2; cat "$work/log-$1x$2-$mode" >&2; exit 1; }
        if [[ $mode == shared-memory ]] && ! grep -q "fields through shared memory" "$work/log-$1x$2-$mode"; then
            echo "the launcher did not choose shared memory for $scene:" >&2
            cat "$work/log-$1x$2-$mode" >&2
            exit 1
        fi
        summary=$(ls "$out"/*.summary.json)
        # Set-up and final messages (homogenized operators, interface solutions) are not per iteration.
        bytes=$(grep -v 'homogenized_operator\|interface_solution' "$work/log-$1x$2-$mode" |
            grep -o '[0-9]* bytes per iteration' | awk '{s += $1} END {if (NR) printf "%.1f", s / 1e6}' || true)
        python3 - "$summary" "$peak" "$(($1 * $2))" "$mode" "${bytes:-}" "$interfaces" <<'EOF'
import json, statistics, sys
d = json.load(open(sys.argv[1]))
peak_kb, n, mode, bytes_, interfaces = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5], int(sys.argv[6])
t = [h["elapsed_s"] for h in d["history"]]
# Iteration k's time is t[k] − t[k−1]; from the 3rd iteration (k = 2) on.
steps = [b - a for a, b in zip(t, t[1:])][1:]
median = statistics.median(steps) * 1e3 if steps else float("nan")
print(f"| {n} | {interfaces} | {mode} | {d['iterations']} ({d['verdict']}) | {d['setup_s']:.2f} | {d['solve_s']:.2f} | "
      f"{median:.1f} | {median / n:.3f} | {median / interfaces:.3f} | {peak_kb / 1e6:.2f} | {bytes_ or '—'} |")
EOF
    done
done
