"""pymodbus updates the simulated drive's firmware: the image in file records (0x15), the state
and progress in 0x2250-0x2255, the install (0x2256 = 2), the new version read back (0x2259);
a corrupted image refused with exception 03 and its reason.

Usage: pymodbus_update.py ENDPOINT IMAGE   (IMAGE signed with the repository's test key for the
simulator: `cargo xtask sign --key keys/test.key --board sim ...`). Exits non-zero on any
failure.
"""

import struct
import sys
import time

from pymodbus.pdu.file_message import FileRecord

from master import check, connect, finish

ENDPOINT, IMAGE = sys.argv[1], sys.argv[2]
DEV = 1
# 122 registers a request, and a record stays within its file of 10 000 registers.
RECORD, FILE = 244, 20_000


def regs(rr):
    return None if rr.isError() else list(rr.registers)


def u32(r, i):
    return (r[i] << 16) | r[i + 1]


def send(client, image):
    """Sends `image` record by record; the first error reply, or None."""
    at = 0
    while at < len(image):
        n = min(RECORD, len(image) - at, FILE - at % FILE)
        data = image[at : at + n]
        if len(data) % 2:
            data += b"\0"
        reg = at // 2
        rec = FileRecord(file_number=reg // 10_000 + 1, record_number=reg % 10_000, record_data=data)
        w = client.write_file_record([rec], device_id=DEV)
        if w.isError():
            return w
        at += n
    return None


image = open(IMAGE, "rb").read()
version = struct.unpack_from("<I", image, 8)[0]
client = connect(ENDPOINT)

r = regs(client.read_holding_registers(0x2250, count=12, device_id=DEV))
check("idle, taking the test key's images", r is not None and r[0] == 0 and r[11] == 1, r)
was = u32(r, 9) if r else None

# A corrupted image: refused at its last record, with the reason; nothing to install.
bad = bytearray(image)
bad[100] ^= 1
e = send(client, bytes(bad))
check("corrupted -> 03", e is not None and getattr(e, "exception_code", None) == 3, e)
r = regs(client.read_holding_registers(0x2250, count=2, device_id=DEV))
check("failed: its signature (4, 4)", r == [4, 4], r)
e = client.write_register(0x2256, 2, device_id=DEV)
check("nothing to install -> 04", e.isError() and getattr(e, "exception_code", None) == 4)

# The image whole: ready, its bytes and version.
t0 = time.monotonic()
e = send(client, image)
took = time.monotonic() - t0
check(f"sent {len(image)} bytes in {took:.2f} s", e is None, e)
r = regs(client.read_holding_registers(0x2250, count=9, device_id=DEV))
ok = r is not None and r[0] == 3 and u32(r, 2) == len(image) and u32(r, 4) == len(image) and u32(r, 7) == version
check("ready, whole, its version", ok, r)

# Installed: the drive restarts into it and says so.
w = client.write_register(0x2256, 2, device_id=DEV)
check("install", not w.isError(), w)
now = None
for _ in range(50):
    time.sleep(0.1)
    r = regs(client.read_holding_registers(0x2259, count=2, device_id=DEV))
    if r is not None:
        now = u32(r, 0)
        if now == version:
            break
check(f"running {version:#08x} (was {was:#08x})", now == version, now)

finish(client, "pymodbus update")
