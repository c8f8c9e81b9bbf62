#!/bin/sh
# The README's scope picture: a move under the servo loop, captured by the drive's own scope in the
# simulator and read out by drivectl over TCP (docs/img/scope-servo.png). From the repository root:
#   sh docs/scripts/scope-picture.sh
set -e
cargo build -q --release -p hal-sim -p drivectl
bin=target/release
flash=$(mktemp)
at=127.0.0.1:15502
drivectl="$bin/drivectl --tcp $at"
$bin/hal-sim --tcp $at --flash "$flash" >/dev/null & sim=$!
sleep 0.5
# Closed loop on the simulated motor's encoder, the servo loop (PID): saved, then a restart.
$drivectl set feedback=1 torque-loop=1
$drivectl save
kill $sim; wait $sim 2>/dev/null || true
$bin/hal-sim --tcp $at --flash "$flash" >/dev/null & sim=$!
sleep 0.5
$drivectl scope --signals commanded-position,actual-position,following-error,commanded-velocity,actual-velocity,loop-output \
    --divider 20 --trigger move --pre 5 --move 4000 --speed 20000 --png docs/img/scope-servo.png
kill $sim
rm -f "$flash"
