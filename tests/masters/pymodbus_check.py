"""A master we did not write (pymodbus) talks to the simulated drive.

Usage: pymodbus_check.py ENDPOINT   where ENDPOINT is a pseudo-terminal path or HOST:PORT
(raw RTU frames over TCP). Prints one line per check and a closing 'N passed, M failed' line;
exits non-zero on any failure.
"""

import sys
import time

from master import check, connect, finish

ENDPOINT = sys.argv[1]
DEV = 1


def regs(rr):
    return None if rr.isError() else list(rr.registers)


client = connect(ENDPOINT)

# Factory state: resolution 0, phase current 658 mA.
r = regs(client.read_holding_registers(0x600C, count=2, device_id=DEV))
check("read 0x600C..D", r == [0, 658], r)

# §9.3: write 0x600C = 32, then read it back through function 0x04.
w = client.write_register(0x600C, 32, device_id=DEV)
check("write 0x600C = 32", not w.isError())
r = regs(client.read_input_registers(0x600C, count=1, device_id=DEV))
check("read back 0x600C", r == [32], r)

# A 32-bit object in one atomic 0x10: speed 32000 pps, high word first.
w = client.write_registers(0x6003, [0, 32000], device_id=DEV)
r = regs(client.read_holding_registers(0x6003, count=2, device_id=DEV))
check("0x6003..4 = 32000", not w.isError() and r == [0, 32000], r)

# Read/write multiple (0x17): write 0x6008..9, read them back in the same request.
rw = client.readwrite_registers(
    read_address=0x6008, read_count=2, write_address=0x6008, values=[700, 800], device_id=DEV
)
check("0x17 read/write", regs(rw) == [700, 800], regs(rw))

# Exceptions, with the state read back unchanged.
e = client.write_register(0x600C, 257, device_id=DEV)
check("out of range -> 03", e.isError() and getattr(e, "exception_code", None) == 3)
e = client.read_holding_registers(0x0000, count=1, device_id=DEV)
check("unknown address -> 02", e.isError() and getattr(e, "exception_code", None) == 2)
e = client.write_register(0x605F, 1, device_id=DEV)
check("read-only -> 02", e.isError() and getattr(e, "exception_code", None) == 2)
r = regs(client.read_holding_registers(0x600C, count=1, device_id=DEV))
check("state unchanged after exceptions", r == [32], r)

# Block read across reserved registers.
r = regs(client.read_holding_registers(0x6000, count=125, device_id=DEV))
check("read 125 registers", r is not None and len(r) == 125 and r[0x0C] == 32, None if r is None else len(r))

# Device identification (0x2B / 0x0E).
rd = client.read_device_information(read_code=1, object_id=0, device_id=DEV)
info = {} if rd.isError() else rd.information
check("device identification", info.get(0) == b"OpenStep Motion", info)

# The scope (0x2220-0x2237): commanded position and velocity, a row every 40 ticks (2 ms),
# triggered by the move's start with 10 % before it; then a move of 3200 microsteps at 32000 pps.
client.write_registers(0x2220, [1, 4, 0, 0, 0, 0, 0, 0], device_id=DEV)
client.write_registers(0x2228, [40, 1], device_id=DEV)  # divider, trigger: a move's start
client.write_register(0x222D, 10, device_id=DEV)
w = client.write_register(0x222F, 1, device_id=DEV)
r = regs(client.read_holding_registers(0x2230, count=2, device_id=DEV))
check("scope armed", not w.isError() and r is not None and r[0] == 1, r)
time.sleep(0.5)  # the share before the trigger fills
client.write_registers(0x6005, [0, 3200], device_id=DEV)
head = None
for _ in range(100):
    head = regs(client.read_holding_registers(0x2230, count=8, device_id=DEV))
    if head is not None and head[0] == 3:
        break
    time.sleep(0.1)
check("scope done", head is not None and head[0] == 3, head)
state, seq, _, rows, width, trig = head[:6]
words = []
while len(words) < rows * width:
    n = min(125, rows * width - len(words))
    words += regs(client.read_holding_registers(0x4000 + len(words), count=n, device_id=DEV)) or []
again = regs(client.read_holding_registers(0x2230, count=2, device_id=DEV))
check("the capture is whole", again == [3, seq] and len(words) == rows * width, again)


def s32(hi, lo):
    v = (hi << 16) | lo
    return v - (1 << 32) if v >= 1 << 31 else v


pos = [s32(words[i], words[i + 1]) for i in range(0, len(words), width)]
vel = [s32(words[i + 2], words[i + 3]) for i in range(0, len(words), width)]
check("standing before the trigger", all(v == 0 for v in vel[:trig]) and vel[trig] > 0, vel[trig - 2 : trig + 2])
check("ends on the target", pos[-1] == pos[0] + 3200, (pos[0], pos[-1]))
steps = [b - a for a, b in zip(pos, pos[1:])]
check("never beyond 32000 pps (64 a row)", all(0 <= d <= 64 for d in steps), max(steps))
e = client.write_register(0x2220, 16, device_id=DEV)
check("no signal 16 -> 03", e.isError() and getattr(e, "exception_code", None) == 3)
w = client.write_register(0x2232, seq, device_id=DEV)
r = regs(client.read_holding_registers(0x2230, count=1, device_id=DEV))
check("read: idle", not w.isError() and r == [0], r)

finish(client, "pymodbus")
