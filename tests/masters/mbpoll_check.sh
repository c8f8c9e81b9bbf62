#!/usr/bin/env bash
# A master we did not write (Debian's mbpoll) talks to the simulated drive on a pseudo-terminal.
# Usage: mbpoll_check.sh PTY. Prints one line per check and 'N passed, M failed'.
set -u
pty=$1
common=(-m rtu -a 1 -b 9600 -P none -0 -1 -o 2)
passed=0 failed=0
check() { # name, expected regex, command...
  local name=$1 want=$2; shift 2
  local out; out=$("$@" 2>&1); local rc=$?
  if [[ $out =~ $want ]]; then echo "ok   $name"; passed=$((passed + 1));
  else echo "FAIL $name (exit $rc)"; echo "$out" | sed 's/^/    /'; failed=$((failed + 1)); fi
}
# Factory values: 0x600C = 0 (24588), 0x600D = 658.
check "read 0x600C..D" $'\\[24588\\]:[[:space:]]+0\n\\[24589\\]:[[:space:]]+658' mbpoll "${common[@]}" -t 4 -r 24588 -c 2 "$pty"
check "write 0x6008 = 900" "Written 1 references" mbpoll "${common[@]}" -t 4 -r 24584 "$pty" 900
check "read back 0x6008" $'\\[24584\\]:[[:space:]]+900' mbpoll "${common[@]}" -t 4 -r 24584 -c 1 "$pty"
check "32-bit speed, two registers" "Written 2 references" mbpoll "${common[@]}" -t 4 -r 24579 "$pty" 1 30000
check "read back speed 96000 = 0x0001_7530" $'\\[24579\\]:[[:space:]]+1\n\\[24580\\]:[[:space:]]+30000' mbpoll "${common[@]}" -t 4 -r 24579 -c 2 "$pty"
check "out of range -> exception" "Illegal data value" mbpoll "${common[@]}" -t 4 -r 24588 "$pty" 257
check "unknown address -> exception" "Illegal data address" mbpoll "${common[@]}" -t 4 -r 0 -c 1 "$pty"
check "other slave -> timeout" "timeout|Connection timed out" mbpoll -m rtu -a 9 -b 9600 -P none -0 -1 -o 1 -t 4 -r 24588 "$pty"
echo "mbpoll: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
