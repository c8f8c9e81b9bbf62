"""A master we did not write (pymodbus) talks to the simulated drive.

Usage: pymodbus_check.py ENDPOINT   where ENDPOINT is a pseudo-terminal path or HOST:PORT
(raw RTU frames over TCP). Prints one line per check and a closing 'N passed, M failed' line;
exits non-zero on any failure.
"""

import sys

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

finish(client, "pymodbus")
