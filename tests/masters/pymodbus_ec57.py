"""A master we did not write (pymodbus) configures the simulator on the EC-57 map (seed 003).
No stock master speaks the EC-57's sub-index byte, so its three requests are pymodbus custom
PDUs (the way pymodbus documents for a vendor's functions), framed, timed and CRC-checked by
pymodbus's own RTU framer: every frame of §1.3 compared byte for byte on the wire, each
exception of §1.3.4 with the state read back unchanged, settings that act (the resolution, the
standstill current), a run beyond the overspeed limit refused with 0x201F saying why, the
position commands counted while the window moves the motor, a run through the command filter
ending on the same pulse, and the map switched back to the native one.

Usage: pymodbus_ec57.py ENDPOINT [mask]   where ENDPOINT is a pseudo-terminal path or HOST:PORT
of `hal-sim --map ec57`. With `mask`, the fault detection mask 0x201B alone, against a simulator
whose supply steps to 70 V two seconds after power-up (`--fault 2000:supply=70`): masked, the
over-voltage latches nothing; unmasked, it latches alarm 14. Prints one line per check and
'N passed, M failed'; exits non-zero on any failure.
"""

import struct
import sys
import time

from master import check, connect, finish
from pymodbus.pdu import ModbusPDU

ENDPOINT = sys.argv[1]
DEV = 1


class Read(ModbusPDU):
    """03 with a sub-index: index, sub-index, count; the reply is Modbus's."""

    function_code = 0x03
    rtu_byte_count_pos = 2

    def __init__(self, index=0, sub=0, count=1, dev_id=DEV, transaction_id=0):
        super().__init__(dev_id=dev_id, transaction_id=transaction_id, address=index, count=count)
        self.sub = sub

    def encode(self):
        return struct.pack(">HBH", self.address, self.sub, self.count)

    def decode(self, data):
        n = data[0]
        self.registers = [struct.unpack(">H", data[1 + i : 3 + i])[0] for i in range(0, n, 2)]


class WriteOne(ModbusPDU):
    """06 with a sub-index; the reply echoes index, sub-index and value (9 bytes a frame)."""

    function_code = 0x06
    rtu_frame_size = 9

    def __init__(self, index=0, sub=0, value=0, dev_id=DEV, transaction_id=0):
        super().__init__(dev_id=dev_id, transaction_id=transaction_id, address=index)
        self.sub, self.value = sub, value

    def encode(self):
        return struct.pack(">HBH", self.address, self.sub, self.value)

    def decode(self, data):
        self.address, self.sub, self.value = struct.unpack(">HBH", data[:5])


class WriteMany(ModbusPDU):
    """16 with a sub-index; the reply echoes index, sub-index and count (9 bytes a frame)."""

    function_code = 0x10
    rtu_frame_size = 9

    def __init__(self, index=0, sub=0, values=(), dev_id=DEV, transaction_id=0):
        super().__init__(dev_id=dev_id, transaction_id=transaction_id, address=index, registers=list(values))
        self.sub = sub

    def encode(self):
        body = struct.pack(">HBHB", self.address, self.sub, len(self.registers), 2 * len(self.registers))
        return body + b"".join(struct.pack(">H", v & 0xFFFF) for v in self.registers)

    def decode(self, data):
        self.address, self.sub, self.count = struct.unpack(">HBH", data[:5])


class Unknown(ModbusPDU):
    """§1.3.4 (2)'s request of function 02, as printed."""

    function_code = 0x02
    rtu_frame_size = 9

    def encode(self):
        return bytes([0x00, 0x00, 0x00, 0x00, 0x04])

    def decode(self, data):
        pass


client = connect(ENDPOINT)
for pdu in (Read, WriteOne, WriteMany):
    client.register(pdu)

# The bytes pymodbus puts on the wire and takes off it, to compare with the manual's frames
# (what it has received so far, each time it tries to frame a reply).
wire = []


def trace(sending, data):
    wire.append((sending, bytes(data)))
    return data


client.transaction.trace_packet = trace


def frames(request):
    """The request's frame and its reply's as pymodbus sent and received them, and the reply."""
    wire.clear()
    reply = client.execute(False, request)
    sent = [d for s, d in wire if s]
    got = [d for s, d in wire if not s]
    return (sent[-1] if sent else b""), (got[-1] if got else b""), reply


def hexs(text):
    return bytes.fromhex(text)


def code(reply):
    return reply.exception_code if reply.isError() else 0


def read(index, sub=0, n=1):
    r = client.execute(False, Read(index, sub, n))
    return None if r.isError() else list(r.registers)


def write(index, sub, value):
    return code(client.execute(False, WriteOne(index, sub, value)))


def relative_run(name):
    """The window's relative run (0x21A0 = 2) to 0x21A1, waited for (20 s at most): the native
    position 0x600E's two registers at its end."""
    check(name, write(0x21A0, 0xFF, 2) == 0)
    end = time.time() + 20
    while time.time() < end and read(0x21AE, 0xFF) == [3]:
        time.sleep(0.05)
    return read(0x600E, 0xFF, 2)


if sys.argv[2:] == ["mask"]:
    check("0x201B reads 0xC3 (factory)", read(0x201B) == [0xC3])
    check("0x201B = 0x01C3 refused (06: bit 8 has no detection)", write(0x201B, 0, 0x01C3) == 6)
    check("0x201B = 0xC1: the over-voltage masked", write(0x201B, 0, 0xC1) == 0)
    end = time.time() + 10
    while time.time() < end and read(0x200D)[0] <= 60:
        time.sleep(0.05)
    supply = read(0x200D)
    check("the supply rose beyond the 60 V over-voltage level (0x200D)", supply[0] > 60, supply)
    time.sleep(0.2)
    check("masked: no alarm in 0x201C.1", read(0x201C, 1) == [0])
    check("masked: the drive enabled (native 0x6011 reads 1)", read(0x6011, 0xFF) == [1])
    check("0x201B = 0xC3: detected again", write(0x201B, 0, 0xC3) == 0)
    time.sleep(0.2)
    check("unmasked: the over-voltage latched, alarm 14 in 0x201C.1", read(0x201C, 1) == [14])
    finish(client, "pymodbus_ec57 mask")

# §1.3's frames, byte for byte (the 4-register read needs 0x2001 = 2 and 0x2003.1 = 500).
sent, got, _ = frames(Read(0x2000, 0, 1))
check("§1.3.1 (1) read 0x2000", (sent, got) == (hexs("01 03 20 00 00 00 01 4B F4"), hexs("01 03 02 00 01 79 84")), got.hex())
check("0x2001 = 2", write(0x2001, 0, 2) == 0)
check("0x2003.1 = 500", write(0x2003, 1, 500) == 0)
sent, got, _ = frames(Read(0x2000, 0, 4))
check(
    "§1.3.1 (2) read 4 from 0x2000",
    (sent, got) == (hexs("01 03 20 00 00 00 04 8B F7"), hexs("01 03 08 00 01 00 02 00 00 01 F4 FC C0")),
    got.hex(),
)
sent, got, _ = frames(WriteOne(0x2005, 0, 10000))
check("§1.3.2 (1) 0x2005 = 10000", sent == got == hexs("01 06 20 05 00 27 10 90 91"), got.hex())
sent, got, _ = frames(WriteOne(0x2003, 1, 50))
check("§1.3.2 (2) 0x2003.1 = 50", sent == got == hexs("01 06 20 03 01 00 32 5A 30"), got.hex())
sent, got, _ = frames(WriteMany(0x2000, 0, [1, 1]))
check(
    "§1.3.3 0x2000, 0x2001 = 1, 1",
    (sent, got) == (hexs("01 10 20 00 00 00 02 04 00 01 00 01 AC 49"), hexs("01 10 20 00 00 00 02 09 56")),
    got.hex(),
)
sent, got, _ = frames(WriteOne(0x2030, 0, 1))
check("§1.3.2 (2) 0x2030 = 1 (save)", sent == got == hexs("01 06 20 30 00 00 01 44 A1"), got.hex())
time.sleep(0.2)

# §1.3.4's exceptions as printed, the state unchanged.
before = read(0x2000, 0, 16)
for name, request, reply in [
    ("(2) function 02", Unknown(dev_id=DEV), "01 82 02 C1 61"),
    ("(3) 0x2031", Read(0x2031, 0, 1), "01 83 03 01 31"),
    ("(4) 32 registers", Read(0x2000, 0, 0x20), "01 83 04 40 F3"),
    ("(5) read of 0x2030", Read(0x2030, 0, 1), "01 83 05 81 33"),
    ("(6) 0x2001 = 8", WriteOne(0x2001, 0, 8), "01 86 06 C2 62"),
]:
    sent, got, r = frames(request)
    check(f"§1.3.4 {name}", got == hexs(reply), got.hex())
check("nothing changed", read(0x2000, 0, 16) == before)

# Settings act: 0x2005 is the drive's resolution, 0x2003.2 its standstill current.
check("0x2005 reads 10000", read(0x2005) == [10000])
check("0x2005 = 10001 refused (06)", write(0x2005, 0, 10001) == 6)
check("native 0x600C through the window: 50", read(0x600C, 0xFF) == [50])
check("0x2003.2 = 40", write(0x2003, 2, 40) == 0 and read(0x2102, 0xFF) == [40])

# 0x2023.1-5: the inputs' filter times, µs, one request.
check("0x2023.1-5 read 1000 µs each (factory)", read(0x2023, 1, 5) == [1000] * 5)
check("0x2023.3 = 49 refused (06)", write(0x2023, 3, 49) == 6)
check("0x2023.3 = 5000", write(0x2023, 3, 5000) == 0 and read(0x21FB, 0xFF) == [5000])

# 0x2012: a run beyond the overspeed limit does not start, and 0x201F says why (30).
check("0x2012 reads 1600 r/min (factory)", read(0x2012) == [1600])
check("0x2012 = 3001 refused (06)", write(0x2012, 0, 3001) == 6)
check("0x2012 = 10 r/min", write(0x2012, 0, 10) == 0)
r = client.execute(False, WriteMany(0x21A1, 0xFF, [0, 10000]))
check("command target 10000 (window)", not r.isError())
at = read(0x600E, 0xFF, 2)
check("a run at 2000 pulses/s (12 r/min) refused (06)", write(0x21A0, 0xFF, 2) == 6)
time.sleep(0.3)
check("nothing moved", read(0x600E, 0xFF, 2) == at)
check("0x201F reads 30 (command overspeed)", read(0x201F) == [30])
check("0x2012 = 1600 again", write(0x2012, 0, 1600) == 0)

# The window moves the motor; 0x2010/0x2011 count the position commands.
check("clear the count (0x2011 = 1)", write(0x2011, 0, 1) == 0)
r = client.execute(False, WriteMany(0x21A1, 0xFF, [0, 10000]))
check("command target 10000 (window)", not r.isError())
position = relative_run("relative run (0x21A0 = 2)")
check("the axis went 10000 pulses (one turn)", position == [0, 10000], position)
check("0x2010/0x2011 count 10000", read(0x2010, 0, 2) == [0, 10000])
speed = read(0x2017)
check("0x2017 at rest 0 r/min", speed == [0], speed)

# 0x2015/0x2016: the same run through the command filter (25.6 ms) ends on the same pulse.
check("0x2015, 0x2016 read 0, 1000 (factory)", read(0x2015, 0, 2) == [0, 1000])
check("0x2016 = 25601 refused (06)", write(0x2016, 0, 25601) == 6)
check("0x2016 = 25600", write(0x2016, 0, 25600) == 0)
check("0x2015 = 1 (filter on)", write(0x2015, 0, 1) == 0)
position = relative_run("relative run (0x21A0 = 2) through the filter")
check("the axis went 10000 pulses more, exactly", position == [0, 20000], position)
check("0x2015 = 0 (filter off)", write(0x2015, 0, 0) == 0)

# Back to the native map: 0x2190 in the window, saved.
check("0x2190 = 0 (window)", write(0x2190, 0xFF, 0) == 0)
check("save (0x2030 = 1)", write(0x2030, 0, 1) == 0)
finish(client, "pymodbus_ec57")
