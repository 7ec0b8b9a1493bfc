#!/usr/bin/env bash
# A new user's path, timed: from `git clone` to their own linkage recorded and replayed.
#
#   benchmarks/new_user_path.sh [REPOSITORY] [WORKDIR]
#
# Clones REPOSITORY (default: this checkout) into WORKDIR (default: a new temporary
# directory), runs `make install`, writes a linkage of the user's own (a steel packaging
# four-bar, not in config/), checks it (`flexlink modes`), plans it (`flexlink plan --quick
# --params-out`), starts the node with that parameters file and the crank driver at 600 rpm
# for STREAM_S seconds recording run1, then `flexlink mcap-info` and `flexlink replay` with
# no model flag. Prints each step's wall time; a step that fails stops the script.
# LINKAGE=FILE uses that mechanism file (with its crank_speed_rpm) in place of the steel one.
# ROS stays on this machine: LOCALHOST discovery and a run-unique domain id.
set -euo pipefail

REPOSITORY=${1:-$(git -C "$(dirname "$0")/.." rev-parse --show-toplevel)}
WORKDIR=${2:-$(mktemp -d -t flexlink-new-user.XXXXXX)}
STREAM_S=${STREAM_S:-5}
LINKAGE=${LINKAGE:+$(realpath "$LINKAGE")}
RPM=600.0
if [[ -n $LINKAGE ]]; then
    RPM=$(sed -n 's/^crank_speed_rpm: *\([0-9.e+]*\).*/\1/p' "$LINKAGE")
    [[ -n $RPM ]] || { echo "$LINKAGE states no crank_speed_rpm" >&2; exit 2; }
    RPM=$(printf '%.1f' "$RPM")     # a ROS double parameter needs its decimal point
fi
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((RANDOM % 102))}
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
TIMES=()

step() {   # step NAME COMMAND...: run, time, remember
    local name=$1 start end
    shift
    echo "== $name: $*" >&2
    start=$(date +%s.%N)
    "$@"
    end=$(date +%s.%N)
    TIMES+=("$(printf '%-28s %7.1f s' "$name" "$(echo "$end - $start" | bc)")")
}

write_linkage() {
    if [[ -n $LINKAGE ]]; then
        cp "$LINKAGE" my_linkage.yaml
        return
    fi
    cat > my_linkage.yaml <<'EOF'
# 20 x 6 mm steel bars, the 20 mm side in the plane: A = 0.006 * 0.020, I = 0.006 * 0.020^3 / 12
name: my_packaging_linkage
source: "a new user's own linkage"
ground_length_m: 0.22
material: {youngs_modulus_pa: 2.1e+11, density_kg_m3: 7850.0}
links:
  crank:   {length_m: 0.06, area_m2: 1.2e-4, second_moment_m4: 4.0e-9}
  coupler: {length_m: 0.25, area_m2: 1.2e-4, second_moment_m4: 4.0e-9}
  lever:   {length_m: 0.18, area_m2: 1.2e-4, second_moment_m4: 4.0e-9}
joint_masses_kg: {O2: 0.02, A: 0.02, B: 0.02, O4: 0.02}
bearings: {stiffness_n_m: 5.0e+7}
gravity_m_s2: [0.0, -9.81]
damping_ratio: 0.02
elements_per_link: 3
crank_speed_rpm: 600.0
EOF
}

wait_for_line() {   # wait_for_line FILE TEXT PID TIMEOUT_S
    local deadline=$((SECONDS + $4))
    until grep -q "$2" "$1"; do
        kill -0 "$3" 2>/dev/null || { cat "$1" >&2; return 1; }
        ((SECONDS < deadline)) || { echo "no '$2' in $4 s" >&2; cat "$1" >&2; return 1; }
        sleep 0.1
    done
}

node_and_driver() {
    .venv/bin/flexlink_node --ros-args --params-file my_node.yaml \
        -p record.enabled:=true -p record.path:=run1 > node.log 2>&1 &
    local node=$!
    wait_for_line node.log 'ready: listening on' "$node" 600
    ".venv/bin/crank_driver" --ros-args -p speed_rpm:="$RPM" > driver.log 2>&1 &
    local driver=$!
    wait_for_line node.log 'first crank sample' "$node" 60
    sleep "$STREAM_S"
    kill -INT "$driver" && wait "$driver" || true
    kill -INT "$node"
    wait "$node"
}

step 'git clone' git clone -q "$REPOSITORY" "$WORKDIR/flexlink_ros"
cd "$WORKDIR/flexlink_ros"
step 'make install' make -s install
step 'write my_linkage.yaml' write_linkage
step 'flexlink modes' .venv/bin/flexlink modes --mechanism my_linkage.yaml --crank-deg 0:360:45
step 'flexlink plan --quick' .venv/bin/flexlink plan --mechanism my_linkage.yaml \
    --rpm-max "$RPM" --tolerance 0.02 --quick --params-out my_node.yaml
step "node + driver (${STREAM_S} s)" node_and_driver
step 'flexlink mcap-info' .venv/bin/flexlink mcap-info run1
step 'flexlink replay' .venv/bin/flexlink replay run1 --chart run1.png
printf '%s\n' "new user's path in $WORKDIR/flexlink_ros (ROS_DOMAIN_ID $ROS_DOMAIN_ID):" "${TIMES[@]}"
